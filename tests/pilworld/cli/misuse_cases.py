"""The misuses: the cases of the issue "A refused command writes nothing" (``ISSUE_CASES``) and a sweep
over every command (``SWEEP_CASES``, a superset). See :mod:`tests.pilworld.cli.misuse` for how they run.

Classes: ``wrong-kind`` (a folder another command made), ``bad-value`` (a value out of range or of
the wrong form), ``bound`` (a count past its stated limit), ``damaged`` (a damaged or foreign input
file), ``output`` (an output path that cannot be written), ``missing`` (an input that is not there),
``conflict`` (a resume with other settings), ``usage`` (argparse), ``recovery`` (an interrupted earlier
run the command must recover from; exit 0).
"""

from __future__ import annotations

import dataclasses
import json
import sqlite3
from pathlib import Path

from tests.pilworld.cli.misuse import Case

CK = "scripted_step_30k"
NONUTF8 = "{tmp}/caf\udce9"  # a byte (0xe9) that is not UTF-8, as a shell passes it


def _write(rel: str, text: str):  # type: ignore[no-untyped-def]
    def setup(ws: Path, tmp: Path) -> None:
        p = tmp / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)

    return setup


def _info_json(rel: str, value: object):  # type: ignore[no-untyped-def]
    return _write(f"{rel}/meta/info.json", json.dumps(value))


def _interrupted_annotate(ws: Path, tmp: Path) -> None:
    """An annotation database as a start interrupted before its judges were made leaves it."""
    from pilworld.annotate.store import AnnotationStore

    AnnotationStore(tmp / "run")  # schema and secret, no judges
    db = sqlite3.connect(tmp / "run" / "annotations.sqlite")
    with db:
        db.execute("DELETE FROM judges")
    db.close()  # (a connection left open would checkpoint its WAL into the file later)


def _corrupt_first_video(rel: str):  # type: ignore[no-untyped-def]
    def setup(ws: Path, tmp: Path) -> None:
        videos = sorted((tmp / rel / "videos").rglob("*.mp4"))
        data = bytearray(videos[0].read_bytes())
        data[: len(data) // 2] = bytes(len(data) // 2)
        videos[0].write_bytes(bytes(data))

    return setup


PAIRED = ["paired", "run", "--task", "sort_cubes", "--checkpoints", CK, "--subtasks", "1"]
IMAGINE = ["imagine", "--starts", "{ws}/starts", "--checkpoints", CK]
COLLECT = ["sim", "collect", "--task", "sort_cubes", "--checkpoint", CK, "--episodes", "1", "--workers", "1"]
STARTS = ["paired", "record-starts", "--task", "sort_cubes", "--count", "1"]
CV = ["control-video", "--rig", "configs/rig/sim_dual_ur5e.yaml"]

ISSUE_CASES: list[Case] = [
    # -- a refused paired run claims nothing
    Case("paired-into-collection", [*PAIRED, "--out", "{tmp}/c"], "wrong-kind", copies={"c": "coll"}),
    Case(
        "paired-checkpoint-typo",
        [*PAIRED[:4], "--checkpoints", "scripted_step_99k", "--subtasks", "1", "--out", "{tmp}/new"],
        "bad-value",
    ),
    Case("paired-negative-seed", [*PAIRED, "--seed", "-5", "--out", "{tmp}/new"], "bad-value"),
    Case(
        "paired-malformed-ws",
        [*PAIRED[:4], "--checkpoints", "ws://:notaport", "--subtasks", "1", "--out", "{tmp}/new"],
        "bad-value",
    ),
    Case(
        "paired-ws-bad-port",
        [*PAIRED[:4], "--checkpoints", "ws://127.0.0.1:99999", "--subtasks", "1", "--out", "{tmp}/new"],
        "bad-value",
    ),
    # -- one command writing into another's folder
    Case("record-starts-into-paired", [*STARTS, "--out", "{tmp}/p"], "wrong-kind", copies={"p": "paired"}),
    Case("paired-into-imagined", [*PAIRED, "--out", "{tmp}/i"], "wrong-kind", copies={"i": "imag"}),
    Case("collect-into-paired", [*COLLECT, "--out", "{tmp}/p"], "wrong-kind", copies={"p": "paired"}),
    Case("collect-into-starts", [*COLLECT, "--out", "{tmp}/s"], "wrong-kind", copies={"s": "starts"}),
    Case("imagine-into-paired", [*IMAGINE, "--out", "{tmp}/p"], "wrong-kind", copies={"p": "paired"}),
    Case("imagine-into-collection", [*IMAGINE, "--out", "{tmp}/c"], "wrong-kind", copies={"c": "coll"}),
    Case("record-starts-into-collection", [*STARTS, "--out", "{tmp}/c"], "wrong-kind", copies={"c": "coll"}),
    Case("convert-into-paired", ["data", "convert", "{ws}/coll", "{tmp}/p"], "wrong-kind", copies={"p": "paired"}),
    # -- data convert of a second source
    Case(
        "convert-second-source",
        ["data", "convert", "{tmp}/other", "{tmp}/o"],
        "wrong-kind",
        copies={"o": "conv", "other": "coll"},
        guard=["{tmp}/o"],
    ),
    # -- damaged inputs
    Case("paired-wm-truncated", [*PAIRED, "--world-model", "{ws}/bad/wm_truncated", "--out", "{tmp}/new"], "damaged"),
    Case("paired-wm-random", [*PAIRED, "--world-model", "{ws}/bad/wm_random", "--out", "{tmp}/new"], "damaged"),
    Case("imagine-wm-truncated", [*IMAGINE, "--world-model", "{ws}/bad/wm_truncated", "--out", "{tmp}/new"], "damaged"),
    Case("paired-wm-bad-config", [*PAIRED, "--world-model", "{ws}/bad/wm_badjson", "--out", "{tmp}/new"], "damaged"),
    Case(
        "info-wrong-shape-list",
        ["data", "info", "{tmp}/c"],
        "damaged",
        exit=1,
        copies={"c": "coll"},
        setup=_info_json("c", [1, 2]),
    ),
    Case(
        "info-wrong-shape-features",
        ["data", "info", "{tmp}/c"],
        "damaged",
        exit=1,
        copies={"c": "coll"},
        setup=_info_json("c", {"codebase_version": "v3.0", "features": 3, "fps": "x"}),
    ),
    Case(
        "verify-wrong-shape",
        ["data", "verify", "{tmp}/c"],
        "damaged",
        exit=1,
        error_lines=0,
        copies={"c": "coll"},
        setup=_info_json("c", {"codebase_version": "v3.0", "features": [], "total_episodes": "x"}),
    ),
    Case(
        "report-wrong-shape",
        ["report", "{tmp}/p", "--out", "{tmp}/r.html"],
        "damaged",
        copies={"p": "paired"},
        setup=_info_json("p", {"features": None}),
    ),
    Case("cv-empty-actions", [*CV, "--actions", "{ws}/bad/empty.npy", "--out", "{tmp}/o.mp4"], "damaged"),
    Case(
        "cv-empty-previous-state",
        [*CV, "--actions", "{ws}/bad/chunk_ok.npy", "--previous-state", "{ws}/bad/empty.npy", "--out", "{tmp}/o.mp4"],
        "damaged",
    ),
    Case("plan-trials-tiny-half-width", ["plan-trials", "{ws}/paired", "--half-width", "1e-300"], "bad-value"),
    # -- unbounded counts
    Case(
        "annotate-judges-huge",
        ["annotate", "serve", "{tmp}/p", "--judges", "100000000", "--port", "0"],
        "bound",
        copies={"p": "paired"},
    ),
    Case(
        "annotate-status-interrupted",
        ["annotate", "status", "{tmp}/run"],
        "recovery",
        exit=0,
        copies={"run": "paired"},
        setup=_interrupted_annotate,
    ),
    Case(
        "annotate-serve-interrupted",
        ["annotate", "serve", "{tmp}/run", "--port", "0"],
        "recovery",
        copies={"run": "paired"},
        setup=_interrupted_annotate,
        guard=["{tmp}/run"],
    ),
    Case("paired-subtasks-huge", [*PAIRED[:6], "--subtasks", "99999999999999999999", "--out", "{tmp}/new"], "bound"),
    # -- segfault on a non-UTF-8 output path
    Case("cv-nonutf8-out", [*CV, "--actions", "{ws}/bad/chunk_ok.npy", "--out", NONUTF8 + ".png"], "output"),
    Case("sim-show-nonutf8-out", ["sim", "show", "--task", "sort_cubes", "--out", NONUTF8 + ".png"], "output"),
    # -- silent acceptance
    Case(
        "imagine-start-frame-paired",
        [*IMAGINE[:2], "{ws}/paired", *IMAGINE[3:], "--start-frame", "100000", "--out", "{tmp}/new"],
        "bad-value",
    ),
    Case("collect-workers-negative", [*COLLECT[:-2], "--workers", "-1", "--out", "{tmp}/new"], "bad-value"),
    Case("bench-sim-subtasks-zero", ["bench", "sim", "--subtasks", "0"], "bad-value"),
    Case("bench-sim-subtasks-negative", ["bench", "sim", "--subtasks", "-5"], "bad-value"),
    Case("cv-joints-1e6", [*CV, "--actions", "{ws}/bad/chunk_1e6.npy", "--out", "{tmp}/o.png"], "bad-value"),
    # -- raw messages
    Case("collect-out-is-file", [*COLLECT, "--out", "{tmp}/f"], "output", setup=_write("f", "x")),
    Case(
        "cv-out-is-folder",
        [*CV, "--actions", "{ws}/bad/chunk_ok.npy", "--out", "{tmp}/d.png"],
        "output",
        setup=_write("d.png/keep", "x"),
    ),
    Case(
        "report-corrupt-video",
        ["report", "{tmp}/p", "--out", "{tmp}/r.html"],
        "damaged",
        copies={"p": "paired"},
        setup=_corrupt_first_video("p"),
    ),
    Case(
        "convert-corrupt-video",
        ["data", "convert", "{tmp}/c", "{tmp}/o"],
        "damaged",
        copies={"c": "coll"},
        setup=_corrupt_first_video("c"),
    ),
    Case(
        "imagine-starts-bad-json",
        [*IMAGINE[:2], "{tmp}/s", *IMAGINE[3:], "--out", "{tmp}/new"],
        "damaged",
        copies={"s": "starts"},
        setup=_write("s/starts.json", ""),
    ),
    Case(
        "cv-binary-rig",
        [
            "control-video",
            "--rig",
            "{ws}/bad/binary.yaml",
            "--actions",
            "{ws}/bad/chunk_ok.npy",
            "--out",
            "{tmp}/o.png",
        ],
        "damaged",
    ),
    Case("paired-binary-rig", [*PAIRED, "--rig", "{ws}/bad/binary.yaml", "--out", "{tmp}/new"], "damaged"),
    Case("task-check-binary", ["task", "check", "{ws}/bad/binary.yaml"], "damaged", exit=1, error_lines=0),
    Case("report-out-unwritable", ["report", "{ws}/paired", "--out", "/proc/nope/r.html"], "output"),
    Case(
        "debug-usage-error",
        ["--debug", "paired", "run", "--task", "sort_cubes", "--subtasks", "ten", "--out", "{tmp}/new"],
        "usage",
    ),
    Case("debug-bad-value", ["--debug", *PAIRED, "--seed", "-1", "--out", "{tmp}/new"], "bad-value", debug=True),
    Case(
        "debug-damaged-weights",
        ["--debug", *PAIRED, "--world-model", "{ws}/bad/wm_random", "--out", "{tmp}/new"],
        "damaged",
        debug=True,
    ),
]


# ---------------------------------------------------------------------------------------------- the sweep

RIG_FLAG_COMMANDS: dict[str, list[str]] = {
    "control-video": ["control-video", "--actions", "{ws}/bad/chunk_ok.npy", "--out", "{tmp}/o.png"],
    "paired-run": [*PAIRED, "--out", "{tmp}/new"],
    "record-starts": [*STARTS, "--out", "{tmp}/new"],
    "sim-collect": [*COLLECT, "--out", "{tmp}/new"],
    "sim-show": ["sim", "show", "--task", "sort_cubes", "--out", "{tmp}/o.png"],
    "bench-sim": ["bench", "sim"],
    "task-show": ["task", "show", "sort_cubes", "--out", "{tmp}/o.png"],
    "task-try": ["task", "try", "sort_cubes", "--subtasks", "1", "--checkpoints", CK, "--workers", "1"],
    "policy-serve": ["policy", "serve", "--port", "0", "--max-seconds", "1"],
    "robot-check": ["robot", "check"],
    "imagine": [*IMAGINE, "--out", "{tmp}/new"],
}
BAD_RIGS = {
    "missing": "{tmp}/no_such_rig.yaml",
    "binary": "{ws}/bad/binary.yaml",
    "not-yaml": "{ws}/bad/not_yaml.yaml",
    "list": "{ws}/bad/list.yaml",
    "empty": "{ws}/bad/empty.yaml",
    "folder": "{ws}/bad/dir.yaml",
}
TASK_FLAG_COMMANDS: dict[str, tuple[list[str], list[str]]] = {  # (before the task, after it)
    "task-show": (["task", "show"], ["--out", "{tmp}/o.png"]),
    "task-try": (["task", "try"], ["--subtasks", "1", "--checkpoints", CK, "--workers", "1"]),
    "paired-run": (["paired", "run", "--checkpoints", CK, "--subtasks", "1", "--task"], ["--out", "{tmp}/new"]),
    "record-starts": (["paired", "record-starts", "--count", "1", "--task"], ["--out", "{tmp}/new"]),
    "sim-collect": (["sim", "collect", "--checkpoint", CK, "--episodes", "1", "--task"], ["--out", "{tmp}/new"]),
    "sim-show": (["sim", "show", "--task"], ["--out", "{tmp}/o.png"]),
    "bench-sim": (["bench", "sim", "--task"], []),
    "imagine": ([*IMAGINE, "--task"], ["--out", "{tmp}/new"]),
    "control-video": (
        [
            "control-video",
            "--rig",
            "configs/rig/sim_dual_ur5e.yaml",
            "--actions",
            "{ws}/bad/chunk_ok.npy",
            "--style",
            "render+markers+prior",
            "--task",
        ],
        ["--out", "{tmp}/o.png"],
    ),
}
BAD_TASKS = {
    "unknown-name": "sort_cubez",
    "missing-file": "{tmp}/no_such_task.yaml",
    "binary": "{ws}/bad/binary.yaml",
    "not-yaml": "{ws}/bad/not_yaml.yaml",
    "list": "{ws}/bad/list.yaml",
    "ten": "{ws}/bad/ten.yaml",
    "empty": "{ws}/bad/empty.yaml",
    "folder": "{ws}/bad/dir.yaml",
}
# Writers of a run folder, and the folders of other kinds they must refuse (folder name in the workspace).
WRITERS: dict[str, tuple[list[str], str]] = {
    "paired-run": (PAIRED, "paired"),
    "record-starts": (STARTS, "starts"),
    "imagine": (IMAGINE, "imag"),
    "sim-collect": (COLLECT, "coll"),
    "train-composite": (["train", "composite", "--data", "{ws}/coll", "--steps", "1"], "train"),
}
KINDS = {"paired": "paired", "starts": "starts", "imag": "imag", "coll": "coll", "conv": "conv"}


def _other_files(ws: Path, tmp: Path) -> None:
    (tmp / "x").mkdir()
    (tmp / "x" / "notes.txt").write_text("mine\n")


def _a_file(ws: Path, tmp: Path) -> None:
    (tmp / "x").write_text("a file\n")


def _sweep() -> list[Case]:
    cases: list[Case] = list(ISSUE_CASES)
    # -- one writer into another's folder (and into a folder of someone's files, and onto a file)
    for writer, (argv, own) in WRITERS.items():
        for kind, folder in KINDS.items():
            if kind == own:
                continue
            cases.append(Case(f"{writer}-into-{kind}", [*argv, "--out", "{tmp}/x"], "wrong-kind", copies={"x": folder}))
        cases.append(Case(f"{writer}-into-other-files", [*argv, "--out", "{tmp}/x"], "wrong-kind", setup=_other_files))
        cases.append(Case(f"{writer}-onto-file", [*argv, "--out", "{tmp}/x"], "output", setup=_a_file))
        cases.append(Case(f"{writer}-nonutf8", [*argv, "--out", NONUTF8], "output"))
        cases.append(Case(f"{writer}-unwritable", [*argv, "--out", "/proc/pilworld-out"], "output"))
    for kind, folder in KINDS.items():
        if kind != "conv":
            cases.append(
                Case(
                    f"convert-into-{kind}",
                    ["data", "convert", "{ws}/coll", "{tmp}/x"],
                    "wrong-kind",
                    copies={"x": folder},
                )
            )
    cases.append(
        Case("convert-into-other-files", ["data", "convert", "{ws}/coll", "{tmp}/x"], "wrong-kind", setup=_other_files)
    )
    cases.append(Case("convert-onto-file", ["data", "convert", "{ws}/coll", "{tmp}/x"], "output", setup=_a_file))
    cases.append(Case("convert-source-missing", ["data", "convert", "{tmp}/nope", "{tmp}/o"], "missing"))
    cases.append(Case("convert-source-empty-dir", ["data", "convert", "{ws}/bad/empty_dir", "{tmp}/o"], "missing"))
    cases.append(
        Case(
            "convert-into-itself",
            ["data", "convert", "{tmp}/c", "{tmp}/c/out"],
            "bad-value",
            copies={"c": "coll"},
            guard=["{tmp}/c"],
        )
    )
    cases.append(
        Case(
            "convert-append-same",
            ["data", "convert", "{ws}/coll", "{tmp}/o", "--append"],
            "conflict",
            copies={"o": "conv"},
        )
    )
    cases.append(
        Case(
            "convert-other-video-mode",
            ["data", "convert", "{ws}/coll", "{tmp}/o", "--video-mode", "lossless"],
            "conflict",
            copies={"o": "conv"},
        )
    )
    cases.append(
        Case(
            "convert-bad-mapping",
            ["data", "convert", "{ws}/coll", "{tmp}/o", "--mapping", "{ws}/bad/binary.yaml"],
            "damaged",
        )
    )
    cases.append(
        Case(
            "convert-missing-mapping",
            ["data", "convert", "{ws}/coll", "{tmp}/o", "--mapping", "{tmp}/nope.yaml"],
            "missing",
        )
    )
    cases.append(Case("convert-bad-format", ["data", "convert", "{ws}/bad/file.txt", "{tmp}/o"], "bad-value"))
    # -- damaged or missing rig files, for every command that takes --rig
    for command, argv in RIG_FLAG_COMMANDS.items():
        for bad, path in BAD_RIGS.items():
            cases.append(
                Case(f"{command}-rig-{bad}", [*argv, "--rig", path], "damaged" if bad != "missing" else "missing")
            )
    # -- task names and task files, for every command that takes one
    for command, (before, after) in TASK_FLAG_COMMANDS.items():
        for bad, path in BAD_TASKS.items():
            cases.append(
                Case(
                    f"{command}-task-{bad}",
                    [*before, path, *after],
                    "damaged" if bad != "unknown-name" else "bad-value",
                )
            )
    for bad, path in BAD_TASKS.items():
        cases.append(Case(f"task-check-{bad}", ["task", "check", path], "damaged", exit=1, error_lines=0))
    # -- counts and seeds out of their bounds
    bounds: list[tuple[str, list[str], str, list[str]]] = [
        ("paired-run", [*PAIRED[:6], "--out", "{tmp}/new"], "--subtasks", ["0", "-3", "10001", "99999999999999999999"]),
        ("paired-run", [*PAIRED, "--out", "{tmp}/new"], "--seed", ["-1", "4294967296"]),
        ("paired-run", [*PAIRED, "--out", "{tmp}/new"], "--rounds", ["0", "-1", "101"]),
        ("paired-run", [*PAIRED, "--out", "{tmp}/new"], "--steps", ["0", "-2", "1001"]),
        ("record-starts", [*STARTS[:4], "--out", "{tmp}/new"], "--count", ["0", "-1", "10001"]),
        ("record-starts", [*STARTS, "--out", "{tmp}/new"], "--seed", ["-1"]),
        ("record-starts", [*STARTS, "--out", "{tmp}/new"], "--rounds", ["0"]),
        ("imagine", [*IMAGINE, "--out", "{tmp}/new"], "--workers", ["0", "-1", "100000"]),
        ("imagine", [*IMAGINE, "--out", "{tmp}/new"], "--judge-workers", ["0", "-4"]),
        ("imagine", [*IMAGINE, "--out", "{tmp}/new"], "--count", ["0", "-1"]),
        ("imagine", [*IMAGINE, "--out", "{tmp}/new"], "--rounds", ["0"]),
        ("imagine", [*IMAGINE, "--out", "{tmp}/new"], "--steps", ["0"]),
        ("sim-collect", [*COLLECT[:6], "--workers", "1", "--out", "{tmp}/new"], "--episodes", ["0", "-1", "100001"]),
        ("sim-collect", [*COLLECT[:-2], "--out", "{tmp}/new"], "--workers", ["0", "-1", "257"]),
        ("sim-collect", [*COLLECT, "--out", "{tmp}/new"], "--seed", ["-7"]),
        ("sim-show", ["sim", "show", "--task", "sort_cubes", "--out", "{tmp}/o.png"], "--seed", ["-1"]),
        ("sim-show", ["sim", "show", "--task", "sort_cubes", "--out", "{tmp}/o.png"], "--subtask", ["-1", "99"]),
        ("sim-show", ["sim", "show", "--task", "sort_cubes", "--out", "{tmp}/o.png"], "--scale", ["0", "1000"]),
        ("bench-sim", ["bench", "sim"], "--subtasks", ["1001"]),
        ("bench-sim", ["bench", "sim", "--subtasks", "1"], "--workers", ["0", "-2"]),
        ("task-try", ["task", "try", "sort_cubes", "--checkpoints", CK], "--subtasks", ["0", "-1", "1000000"]),
        ("task-try", ["task", "try", "sort_cubes", "--checkpoints", CK, "--subtasks", "1"], "--workers", ["0", "-1"]),
        ("task-show", ["task", "show", "sort_cubes", "--out", "{tmp}/o.png"], "--seed", ["-1"]),
        ("annotate-serve", ["annotate", "serve", "{tmp}/p", "--port", "0"], "--judges", ["0", "-1", "101"]),
        ("annotate-serve", ["annotate", "serve", "{tmp}/p", "--judges", "1"], "--port", ["-1", "70000"]),
        ("plan-trials", ["plan-trials", "{ws}/paired"], "--half-width", ["0", "-0.1", "0.5", "nan", "inf"]),
        ("plan-trials", ["plan-trials", "{ws}/paired", "--half-width", "0.05"], "--alpha", ["0", "1", "-1"]),
        ("report", ["report", "{ws}/paired", "--out", "{tmp}/r.html"], "--max-pairs", ["-1"]),
        ("policy-serve", ["policy", "serve", "--max-seconds", "1"], "--port", ["-1", "65536"]),
        ("policy-serve", ["policy", "serve", "--port", "0"], "--horizon", ["0", "100000"]),
        ("policy-serve", ["policy", "serve", "--port", "0"], "--max-seconds", ["0", "-5"]),
        ("train-composite", ["train", "composite", "--data", "{ws}/coll", "--out", "{tmp}/t"], "--steps", ["0", "-1"]),
        ("train-composite", ["train", "composite", "--data", "{ws}/coll", "--out", "{tmp}/t"], "--batch", ["0"]),
        ("train-pretrain", ["train", "pretrain", "--data", "{ws}/coll", "--out", "{tmp}/t"], "--steps", ["0"]),
        ("train-pretrain", ["train", "pretrain", "--data", "{ws}/coll", "--out", "{tmp}/t"], "--nproc", ["0", "1000"]),
        ("control-video", [*CV, "--actions", "{ws}/bad/chunk_ok.npy", "--out", "{tmp}/o.png"], "--frames", ["0", "-1"]),
        ("control-video", [*CV, "--actions", "{ws}/bad/chunk_ok.npy", "--out", "{tmp}/o.png"], "--stride", ["0"]),
        ("control-video", [*CV, "--actions", "{ws}/bad/chunk_ok.npy", "--out", "{tmp}/o.mp4"], "--fps", ["0", "-1"]),
        (
            "control-video",
            [*CV, "--actions", "{ws}/bad/chunk_ok.npy", "--out", "{tmp}/o.png"],
            "--size",
            ["0x0", "abc"],
        ),
    ]
    for command, argv, flag, values in bounds:
        for value in values:
            cases.append(Case(f"{command}{flag}={value}", [*argv, flag, value], "bound"))
    # -- values of the wrong form (argparse's own refusals: usage, exit 2)
    for command, argv, flag in [
        ("paired-run", [*PAIRED[:6], "--out", "{tmp}/new"], "--subtasks"),
        ("sim-collect", [*COLLECT[:6], "--out", "{tmp}/new"], "--episodes"),
        ("record-starts", [*STARTS[:4], "--out", "{tmp}/new"], "--count"),
        ("annotate-serve", ["annotate", "serve", "{ws}/paired"], "--judges"),
        ("imagine", [*IMAGINE, "--out", "{tmp}/new"], "--workers"),
        ("plan-trials", ["plan-trials", "{ws}/paired"], "--half-width"),
    ]:
        cases.append(Case(f"{command}{flag}=ten", [*argv, flag, "ten"], "usage"))
    cases += [
        Case("paired-bad-video-mode", [*PAIRED, "--video-mode", "gif", "--out", "{tmp}/new"], "usage"),
        Case("paired-bad-appearance", [*PAIRED, "--appearance", "shiny", "--out", "{tmp}/new"], "usage"),
        Case("no-command", [], "usage"),
        Case("unknown-command", ["frobnicate"], "usage"),
        Case("data-no-subcommand", ["data"], "usage"),
    ]
    # -- checkpoints
    for name, value in {
        "typo": "scripted_step_99k",
        "empty": "",
        "comma": ",",
        "trailing-comma": f"{CK},",
        "ws-no-port": "ws://:notaport",
        "ws-port-range": "ws://127.0.0.1:99999",
        "http": "http://127.0.0.1:8000",
    }.items():
        cases.append(
            Case(
                f"paired-checkpoints-{name}",
                [*PAIRED[:4], "--checkpoints", value, "--subtasks", "1", "--out", "{tmp}/new"],
                "bad-value",
            )
        )
        cases.append(
            Case(
                f"imagine-checkpoints-{name}", [*IMAGINE[:3], "--checkpoints", value, "--out", "{tmp}/new"], "bad-value"
            )
        )
    cases.append(
        Case(
            "sim-collect-checkpoint-typo",
            [*COLLECT[:4], "--checkpoint", "scripted_step_99k", "--episodes", "1", "--out", "{tmp}/new"],
            "bad-value",
        )
    )
    cases.append(
        Case(
            "task-try-checkpoint-typo",
            ["task", "try", "sort_cubes", "--checkpoints", "nope", "--subtasks", "1"],
            "bad-value",
        )
    )
    # -- world models
    for bad in ("wm_truncated", "wm_random", "wm_empty", "wm_badjson", "wm_listjson", "empty_dir", "file.txt"):
        cases.append(
            Case(
                f"paired-world-model-{bad}",
                [*PAIRED, "--world-model", "{ws}/bad/" + bad, "--out", "{tmp}/new"],
                "damaged",
            )
        )
        cases.append(
            Case(
                f"imagine-world-model-{bad}",
                [*IMAGINE, "--world-model", "{ws}/bad/" + bad, "--out", "{tmp}/new"],
                "damaged",
            )
        )
    cases.append(
        Case("paired-world-model-missing", [*PAIRED, "--world-model", "{tmp}/nope", "--out", "{tmp}/new"], "missing")
    )
    cases.append(Case("paired-adapter-unknown", [*PAIRED, "--adapter", "nope", "--out", "{tmp}/new"], "bad-value"))
    cases.append(Case("bench-wm-damaged", ["bench", "world-model", "--checkpoint", "{ws}/bad/wm_random"], "damaged"))
    # -- dataset metadata of the wrong shape, for every reader
    shapes = {
        "list": [1, 2],
        "features-int": {"codebase_version": "v3.0", "fps": 10, "features": 3},
        "fps-text": {"codebase_version": "v3.0", "fps": "x", "features": {}},
        "no-fps": {"codebase_version": "v3.0", "features": {}},
        "feature-null": {"codebase_version": "v3.0", "fps": 10, "features": {"action": None}},
    }
    readers: dict[str, tuple[list[str], int, int]] = {  # argv, exit, error lines
        "data-info": (["data", "info", "{tmp}/c"], 1, 1),
        "data-verify": (["data", "verify", "{tmp}/c"], 1, 0),
        "report": (["report", "{tmp}/c", "--out", "{tmp}/r.html"], 2, 1),
        "imagine-starts": ([*IMAGINE[:2], "{tmp}/c", *IMAGINE[3:], "--out", "{tmp}/new"], 2, 1),
        "annotate-serve": (["annotate", "serve", "{tmp}/c", "--judges", "1", "--port", "0"], 2, 1),
        "bench-judges": (["bench", "judges", "{tmp}/c"], 2, 1),
        "convert-source": (["data", "convert", "{tmp}/c", "{tmp}/o"], 2, 1),
        "train-composite-data": (["train", "composite", "--data", "{tmp}/c", "--out", "{tmp}/t", "--steps", "1"], 2, 1),
    }
    for reader, (argv, code, lines) in readers.items():
        for shape, value in shapes.items():
            cases.append(
                Case(
                    f"{reader}-info-{shape}",
                    argv,
                    "damaged",
                    exit=code,
                    error_lines=lines,
                    copies={"c": "coll"},
                    setup=_info_json("c", value),
                    guard=["{tmp}/c"],
                )
            )
    for reader, (argv, _, _) in readers.items():
        if reader in ("data-info", "data-verify"):
            continue  # (a missing input to them is "not a dataset": exit 2)
        cases.append(Case(f"{reader}-missing", [a.replace("{tmp}/c", "{tmp}/nope") for a in argv], "missing"))
    cases += [
        Case("data-info-missing", ["data", "info", "{tmp}/nope"], "missing"),
        Case("data-verify-missing", ["data", "verify", "{tmp}/nope"], "missing"),
        Case("data-info-a-file", ["data", "info", "{ws}/bad/file.txt"], "missing"),
        Case("data-verify-empty-dir", ["data", "verify", "{ws}/bad/empty_dir"], "missing"),
        Case(
            "data-info-bad-json",
            ["data", "info", "{tmp}/c"],
            "damaged",
            exit=1,
            copies={"c": "coll"},
            setup=_write("c/meta/info.json", "{not json"),
        ),
        Case(
            "data-info-bad-pilworld-json",
            ["data", "info", "{tmp}/c"],
            "damaged",
            exit=1,
            copies={"c": "coll"},
            setup=_write("c/meta/pilworld.json", "[]"),
        ),
        Case(
            "report-corrupt-video-2",
            ["report", "{tmp}/p", "--out", "{tmp}/r.html", "--max-pairs", "1"],
            "damaged",
            copies={"p": "paired"},
            setup=_corrupt_first_video("p"),
        ),
        Case("report-not-a-run", ["report", "{ws}/bad/empty_dir"], "missing"),
        Case("report-out-is-folder", ["report", "{ws}/paired", "--out", "{ws}/bad/empty_dir"], "output"),
        Case("report-out-nonutf8", ["report", "{ws}/paired", "--out", NONUTF8 + ".html"], "output"),
        Case(
            "report-imagined-missing",
            ["report", "{tmp}/p", "--imagined", "{tmp}/nope"],
            "missing",
            copies={"p": "paired"},
        ),
        Case(
            "report-imagined-not-imagined",
            ["report", "{tmp}/p", "--imagined", "{ws}/coll"],
            "wrong-kind",
            copies={"p": "paired"},
        ),
        Case("plan-trials-not-paired", ["plan-trials", "{ws}/coll", "--half-width", "0.05"], "wrong-kind"),
        Case("plan-trials-missing", ["plan-trials", "{tmp}/nope", "--half-width", "0.05"], "missing"),
        Case("annotate-serve-not-a-run", ["annotate", "serve", "{ws}/bad/empty_dir", "--judges", "1"], "missing"),
        Case("annotate-status-no-session", ["annotate", "status", "{ws}/paired"], "missing"),
        Case("annotate-export-no-session", ["annotate", "export", "{ws}/paired"], "missing"),
        Case(
            "annotate-serve-remote",
            ["annotate", "serve", "{tmp}/p", "--judges", "1", "--host", "0.0.0.0"],
            "bad-value",
            copies={"p": "paired"},
        ),
        Case("imagine-starts-missing", [*IMAGINE[:2], "{tmp}/nope", *IMAGINE[3:], "--out", "{tmp}/new"], "missing"),
        Case(
            "imagine-starts-empty-dir",
            [*IMAGINE[:2], "{ws}/bad/empty_dir", *IMAGINE[3:], "--out", "{tmp}/new"],
            "missing",
        ),
        Case(
            "imagine-starts-list-json",
            [*IMAGINE[:2], "{tmp}/s", *IMAGINE[3:], "--out", "{tmp}/new"],
            "damaged",
            copies={"s": "starts"},
            setup=_write("s/starts.json", "[1]"),
        ),
        Case("imagine-start-frame-starts", [*IMAGINE, "--start-frame", "3", "--out", "{tmp}/new"], "bad-value"),
        Case(
            "imagine-start-frame-negative",
            [*IMAGINE[:2], "{ws}/coll", *IMAGINE[3:], "--start-frame", "-1", "--out", "{tmp}/new"],
            "bad-value",
        ),
        Case(
            "imagine-start-frame-past-end",
            [*IMAGINE[:2], "{ws}/coll", *IMAGINE[3:], "--start-frame", "100000", "--out", "{tmp}/new"],
            "bad-value",
        ),
        Case(
            "imagine-other-settings", [*IMAGINE, "--rounds", "3", "--out", "{tmp}/i"], "conflict", copies={"i": "imag"}
        ),
        Case(
            "paired-other-settings", [*PAIRED, "--rounds", "3", "--out", "{tmp}/p"], "conflict", copies={"p": "paired"}
        ),
        Case(
            "record-starts-other-settings",
            [*STARTS, "--rounds", "3", "--out", "{tmp}/s"],
            "conflict",
            copies={"s": "starts"},
        ),
        # a damaged setting of a run comes back from meta/backup, then the run resumes: exit 0
        Case(
            "paired-damaged-config",
            [*PAIRED, "--out", "{tmp}/p"],
            "recovery",
            exit=0,
            copies={"p": "paired"},
            setup=_write("p/paired_config.json", "{"),
        ),
        Case(
            "imagine-damaged-config",
            [*IMAGINE, "--out", "{tmp}/i"],
            "recovery",
            exit=0,
            copies={"i": "imag"},
            setup=_write("i/imagine_config.json", ""),
        ),
        Case("paired-instruction-blank", [*PAIRED, "--instruction", "   ", "--out", "{tmp}/new"], "bad-value"),
        Case("paired-instruction-newline", [*PAIRED, "--instruction", "a\nb", "--out", "{tmp}/new"], "bad-value"),
        Case(
            "paired-hardware-appearance",
            [*PAIRED, "--rig", "configs/rig/fake_dual_ur5e.yaml", "--appearance", "varied", "--out", "{tmp}/new"],
            "bad-value",
        ),
        Case("sim-show-out-not-png", ["sim", "show", "--task", "sort_cubes", "--out", "{tmp}/o.jpg"], "output"),
        Case("sim-show-out-folder", ["sim", "show", "--task", "sort_cubes", "--out", "{ws}/bad/empty_dir"], "output"),
        Case("sim-show-out-unwritable", ["sim", "show", "--task", "sort_cubes", "--out", "/proc/x/o.png"], "output"),
        Case("task-show-out-nonutf8", ["task", "show", "sort_cubes", "--out", NONUTF8 + ".png"], "output"),
        Case("task-show-out-not-png", ["task", "show", "sort_cubes", "--out", "{tmp}/o.gif"], "output"),
        Case("cv-out-bad-suffix", [*CV, "--actions", "{ws}/bad/chunk_ok.npy", "--out", "{tmp}/o.gif"], "output"),
        Case("cv-out-unwritable", [*CV, "--actions", "{ws}/bad/chunk_ok.npy", "--out", "/proc/x/o.png"], "output"),
        Case(
            "cv-out-parent-file",
            [*CV, "--actions", "{ws}/bad/chunk_ok.npy", "--out", "{ws}/bad/file.txt/o.png"],
            "output",
        ),
        Case("train-plot-out-nonutf8", ["train", "plot", "{tmp}/t", "--out", NONUTF8 + ".png"], "output"),
        Case(
            "calibrate-board-out-nonutf8",
            ["calibrate", "board", "--config", "configs/board/charuco_7x5_a4.yaml", "--out", NONUTF8],
            "output",
        ),
        Case("policy-serve-port-in-use", ["policy", "serve", "--port", "{busy_port}", "--max-seconds", "1"], "output"),
    ]
    for name, path in {
        "garbage": "{ws}/bad/garbage.npy",
        "nan": "{ws}/bad/chunk_nan.npy",
        "1e6": "{ws}/bad/chunk_1e6.npy",
        "1d": "{ws}/bad/state_1d.npy",
        "missing": "{tmp}/nope.npy",
        "not-npy": "{ws}/bad/file.txt",
        "folder": "{ws}/bad/empty_dir",
    }.items():
        cases.append(Case(f"cv-actions-{name}", [*CV, "--actions", path, "--out", "{tmp}/o.png"], "damaged"))
        cases.append(
            Case(
                f"cv-previous-state-{name}",
                [*CV, "--actions", "{ws}/bad/chunk_ok.npy", "--previous-state", path, "--out", "{tmp}/o.png"],
                "damaged",
            )
        )
    seen: dict[str, int] = {}
    unique = []
    for case in cases:  # the sweep's own cases may repeat an issue case under the same name: keep both
        seen[case.name] = seen.get(case.name, 0) + 1
        unique.append(
            case if seen[case.name] == 1 else dataclasses.replace(case, name=f"{case.name}#{seen[case.name]}")
        )
    return unique


SWEEP_CASES: list[Case] = _sweep()
