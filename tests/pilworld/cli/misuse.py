"""Running misuses of the CLI and classifying what came back (shared by ``test_refusals.py`` and the sweep).

A case is an argv with ``{ws}`` (the shared workspace of real run folders, never written) and ``{tmp}``
(a fresh folder of its own) in it, the exit status it must end with, and the folders that must come out
byte-identical. Each case runs in a forked child of a process that has already imported the CLI, so a
case costs its own work, not Python's start-up; a crash in the child (a segfault) is seen as a signal.

A case fails when stderr holds a traceback, the child died of a signal or ran past its time, the exit
status is not the expected one (an exit 0 on a misuse is *silent acceptance*), stderr's error is not one
``pilworld: error: …`` line, or a guarded folder changed (*loss*).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import traceback
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[3]


# Messages that come from inside a library and name neither the flag nor the file.
RAW_MARKS = (
    "DatasetSpec(",
    "object at 0x",
    "[Errno ",
    "Expecting value",
    "codec can't decode",
    "invalid literal for int()",
    "SafetensorError",
)


@dataclass(frozen=True)
class Case:
    """One misuse: ``argv`` (with ``{ws}``/``{tmp}``), its class, the exit it must end with."""

    name: str
    argv: Sequence[str]
    klass: str
    exit: int = 2
    copies: dict[str, str] = field(default_factory=dict)  # {tmp}/NAME <- {ws}/SOURCE, before the run
    guard: Sequence[str] = ()  # folders/files (formatted) whose tree must not change; --out is added
    setup: Callable[[Path, Path], None] | None = None  # (ws, tmp) -> None, after the copies
    timeout: float = 240.0
    stdin: bytes | None = None
    debug: bool = False  # --debug: a traceback is expected before the one error line
    error_lines: int = 1  # 0 for a checker whose findings go to stdout (task check)


@dataclass
class Result:
    case: Case
    rc: int | None
    signal: int | None
    stdout: str
    stderr: str
    seconds: float
    changed: list[str]
    timed_out: bool = False

    @property
    def error_lines(self) -> list[str]:
        lines = self.stderr.replace("\r", "\n").splitlines()
        return [line for line in lines if line.startswith("pilworld: error:")]

    @property
    def first_line(self) -> str:
        lines = [line for line in self.stderr.replace("\r", "\n").splitlines() if line.strip() and "%|" not in line]
        if self.case.debug and self.error_lines:
            return self.error_lines[0]
        return lines[0] if lines else (self.stdout.splitlines() or [""])[0]

    def problems(self) -> list[str]:
        """What is wrong with this outcome (empty: the case passed)."""
        out = []
        if self.timed_out:
            out.append(f"ran past {self.case.timeout:.0f} s")
        if self.signal is not None:
            out.append(f"killed by signal {self.signal}")
        if "Traceback (most recent call last)" in self.stderr and not self.case.debug:
            out.append("traceback on stderr")
        if self.rc is not None and self.rc != self.case.exit:
            out.append(f"exit {self.rc}, expected {self.case.exit}" + (" (silent acceptance)" if self.rc == 0 else ""))
        if self.rc not in (None, 0) and self.case.exit != 0:
            n = len(self.error_lines)
            usage = self.rc == 2 and any(line.startswith("usage:") for line in self.stderr.splitlines())
            if not usage and n != self.case.error_lines:
                out.append(f"{n} 'pilworld: error:' lines on stderr")
            if usage and not any(": error: " in line for line in self.stderr.splitlines()):
                out.append("usage without an error line")
            text = " ".join(self.error_lines)
            for repr_mark in RAW_MARKS:
                if repr_mark in text:
                    out.append(f"raw message ({repr_mark!r})")
        if self.changed:
            out.append("changed: " + ", ".join(self.changed[:3]))
        return out


def tree_digest(path: Path) -> str:
    """Names, kinds and contents of everything under ``path`` ("absent" when it does not exist)."""
    if not os.path.lexists(path):
        return "absent"
    h = hashlib.sha256()
    if path.is_file():
        h.update(path.read_bytes())
        return "file:" + h.hexdigest()
    for dirpath, dirnames, filenames in sorted(os.walk(path)):
        dirnames.sort()
        rel = os.path.relpath(dirpath, path)
        h.update(f"d {rel}\n".encode(errors="surrogateescape"))
        for name in sorted(filenames):
            full = Path(dirpath) / name
            h.update(f"f {rel}/{name}\n".encode(errors="surrogateescape"))
            if full.is_file():
                h.update(hashlib.sha256(full.read_bytes()).digest())
    return h.hexdigest()


_BUSY: list[socket.socket] = []


def busy_port() -> int:
    """A port this process listens on (for the 'port in use' cases)."""
    if not _BUSY:
        s = socket.socket()
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        _BUSY.append(s)
    return int(_BUSY[0].getsockname()[1])


def _format(text: str, ws: Path, tmp: Path) -> str:
    text = text.replace("{ws}", str(ws)).replace("{tmp}", str(tmp))
    return text.replace("{busy_port}", str(busy_port())) if "{busy_port}" in text else text


def _outs(argv: Sequence[str]) -> list[str]:
    return [argv[i + 1] for i, a in enumerate(argv[:-1]) if a == "--out"]


def _child(argv: list[str], out: Path, err: Path, stdin: Path) -> None:  # pragma: no cover - runs in the fork
    fd_in = os.open(stdin, os.O_RDONLY)
    fd_out = os.open(out, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    fd_err = os.open(err, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    os.dup2(fd_in, 0)
    os.dup2(fd_out, 1)
    os.dup2(fd_err, 2)
    os.environ.pop("PILWORLD_DEBUG", None)
    rc = 1
    try:
        from pilworld.cli.main import main

        rc = main(argv)
    except SystemExit as stop:
        rc = stop.code if isinstance(stop.code, int) else (0 if stop.code is None else 1)
    except BaseException:  # what escapes main is what a user would see as a traceback
        traceback.print_exc()
        rc = 1
    finally:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
    os._exit(rc)


class _ForkServer:
    """A clean process that forks one child per case. Forking the test process itself is unsafe: a lock
    another thread of pytest (a server, torch) holds at the fork stays held in the child forever."""

    def __init__(self) -> None:
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "tests.pilworld.cli.misuse", "--serve"],
            cwd=REPO,
            env=env,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )

    def run(self, argv: Sequence[str], timeout: float, stdin: bytes | None) -> tuple[Any, ...]:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        request = {"argv": list(argv), "timeout": timeout, "stdin": (stdin or b"").decode("latin-1")}
        self.proc.stdin.write(json.dumps(request) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError("the misuse fork server died")
        return tuple(json.loads(line))


_SERVER: list[_ForkServer] = []


def run_argv(
    argv: Sequence[str], *, timeout: float = 240.0, stdin: bytes | None = None
) -> tuple[int | None, int | None, str, str, bool]:
    """``pilworld ARGV`` in a child forked by a clean helper process: (exit, signal, stdout, stderr, timed out)."""
    if not _SERVER or _SERVER[0].proc.poll() is not None:
        _SERVER[:] = [_ForkServer()]
    rc, sig, out, err, timed_out = _SERVER[0].run([os.fsencode(a).decode("latin-1") for a in argv], timeout, stdin)
    return rc, sig, out, err, timed_out


def _serve() -> None:  # pragma: no cover - the fork server's loop
    """Read one JSON request a line, fork the case, write its result as one JSON line."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    preload()
    for line in sys.stdin:
        req = json.loads(line)
        argv = [os.fsdecode(a.encode("latin-1")) for a in req["argv"]]
        result = _fork_run(argv, timeout=req["timeout"], stdin=req["stdin"].encode("latin-1"))
        sys.stdout.write(json.dumps(list(result)) + "\n")
        sys.stdout.flush()


def _fork_run(
    argv: Sequence[str], *, timeout: float = 240.0, stdin: bytes | None = None
) -> tuple[int | None, int | None, str, str, bool]:
    """``pilworld ARGV`` in a forked child: (exit status, signal, stdout, stderr, timed out)."""
    with tempfile.TemporaryDirectory(prefix="misuse-io-") as io_dir:
        out, err, inp = Path(io_dir, "out"), Path(io_dir, "err"), Path(io_dir, "in")
        inp.write_bytes(stdin or b"")
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:  # pragma: no cover - the child
            os.setpgid(0, 0)
            _child(list(argv), out, err, inp)
        deadline = time.monotonic() + timeout
        timed_out = False
        while True:
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                break
            if time.monotonic() > deadline:
                timed_out = True
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(pid, signal.SIGKILL)
                _, status = os.waitpid(pid, 0)
                break
            time.sleep(0.05)
        rc = os.waitstatus_to_exitcode(status)
        sig = -rc if rc < 0 and not timed_out else None
        return (
            None if rc < 0 else rc,
            sig,
            out.read_text(errors="replace"),
            err.read_text(errors="replace"),
            timed_out,
        )


def run_case(case: Case, ws: Path, scratch: Path) -> Result:
    """Run ``case`` with its own ``{tmp}`` under ``scratch``; checks the guarded folders."""
    tmp = Path(tempfile.mkdtemp(prefix=f"{case.name[:40]}-", dir=scratch))
    for name, source in case.copies.items():
        src = ws / source
        if src.is_dir():
            shutil.copytree(src, tmp / name, symlinks=True)
        else:
            shutil.copy2(src, tmp / name)
    if case.setup is not None:
        case.setup(ws, tmp)
    argv = [_format(a, ws, tmp) for a in case.argv]
    guards = [Path(_format(g, ws, tmp)) for g in case.guard]
    guards += [Path(o) for o in _outs(argv) if str(tmp) in o or str(ws) in o]
    guards.append(ws)  # the shared workspace is never written
    before = {g: tree_digest(g) for g in guards}
    t0 = time.monotonic()
    rc, sig, out, err, timed_out = run_argv(argv, timeout=case.timeout, stdin=case.stdin)
    seconds = time.monotonic() - t0
    changed = [str(g) for g in guards if tree_digest(g) != before[g]] if case.exit != 0 else []
    result = Result(case, rc, sig, out, err, seconds, changed, timed_out)
    shutil.rmtree(tmp, ignore_errors=True)
    return result


def build_workspace(ws: Path) -> Path:
    """Real run folders of every kind, built once (about a minute on 2 cores), and damaged inputs."""
    ws.mkdir(parents=True, exist_ok=True)
    steps: list[tuple[str, list[str]]] = [
        ("coll", ["sim", "collect", "--episodes", "1", "--task", "sort_cubes", "--checkpoint", "scripted_step_30k",
                  "--workers", "1", "--out", str(ws / "coll"), "--json"]),
        ("paired", ["paired", "run", "--subtasks", "1", "--checkpoints", "scripted_step_30k", "--task", "sort_cubes",
                    "--out", str(ws / "paired"), "--json"]),
        ("starts", ["paired", "record-starts", "--task", "sort_cubes", "--count", "1", "--out", str(ws / "starts"),
                    "--json"]),
        ("imag", ["imagine", "--starts", str(ws / "starts"), "--checkpoints", "scripted_step_30k", "--out",
                  str(ws / "imag"), "--json"]),
        ("conv", ["data", "convert", str(ws / "coll"), str(ws / "conv"), "--json"]),
    ]  # fmt: skip
    for name, argv in steps:
        if (ws / name / "meta" / "info.json").is_file() and not (ws / f".{name}.partial").exists():
            continue
        (ws / f".{name}.partial").write_text("")
        rc, sig, _, err, _ = run_argv(argv, timeout=600)
        if rc != 0:
            raise RuntimeError(f"building {name} failed ({rc}, {sig}): {err[-2000:]}")
        (ws / f".{name}.partial").unlink()
    _damaged_inputs(ws)
    return ws


def _damaged_inputs(ws: Path) -> None:
    """Files a careless or unlucky user passes: truncated, random, empty, of the wrong shape."""
    import numpy as np

    rng = np.random.default_rng(0)
    bad = ws / "bad"
    if (bad / ".done").is_file():
        return
    shutil.rmtree(bad, ignore_errors=True)
    bad.mkdir()
    wm = REPO / "pilworld" / "world_model" / "weights" / "sim_composite"
    for name, mutate in {
        "wm_truncated": lambda b: b[: len(b) // 3],
        "wm_random": lambda b: rng.bytes(len(b)),
        "wm_empty": lambda b: b"",
    }.items():
        shutil.copytree(wm, bad / name)
        p = bad / name / "model.safetensors"
        p.write_bytes(mutate(p.read_bytes()))
    shutil.copytree(wm, bad / "wm_badjson")
    (bad / "wm_badjson" / "config.json").write_text("")
    shutil.copytree(wm, bad / "wm_listjson")
    (bad / "wm_listjson" / "config.json").write_text("[1, 2]")
    (bad / "empty.npy").write_bytes(b"")
    (bad / "garbage.npy").write_bytes(b"\x93NUMPY garbage that is not an array header")
    np.save(bad / "chunk_1e6.npy", np.full((45, 14), 1e6, dtype=np.float32))
    np.save(bad / "chunk_nan.npy", np.full((45, 14), np.nan, dtype=np.float32))
    np.save(bad / "chunk_ok.npy", np.zeros((45, 14), dtype=np.float32))
    np.save(bad / "state_1d.npy", np.zeros((3,), dtype=np.float32))
    (bad / "binary.yaml").write_bytes(bytes(range(256)) * 4)
    (bad / "not_yaml.yaml").write_text("a: [1, 2\n  b: }")
    (bad / "list.yaml").write_text("- 1\n- 2\n")
    (bad / "ten.yaml").write_text("name: x\nnum_subtasks: ten\n")
    (bad / "empty.yaml").write_text("")
    (bad / "dir.yaml").mkdir()
    (bad / "file.txt").write_text("a file, not a folder\n")
    (bad / "empty_dir").mkdir()
    (bad / "corrupt.mp4").write_bytes(rng.bytes(4096))
    (bad / "lerobot_src").mkdir()
    (bad / ".done").write_text("")


def run_cases(
    cases: Iterable[Case], ws: Path, scratch: Path, *, on_result: Callable[[Result], None] | None = None
) -> list[Result]:
    results = []
    for case in cases:
        r = run_case(case, ws, scratch)
        results.append(r)
        if on_result is not None:
            on_result(r)
    return results


def preload() -> None:
    """Import what most commands import, once, in the parent (each fork then starts warm)."""
    import importlib

    for name in ("numpy", "torch", "pilworld.cli.main", "pilworld.data.reader", "pilworld.paired.runner"):
        importlib.import_module(name)


def build_marker_workspace(ws: Path) -> Path:
    """A cheap stand-in for :func:`build_workspace`: folders of every kind holding only their markers and
    a dataset's ``meta/info.json`` (no episodes). Refusals that happen before a command reads any data
    run against it in seconds; the others need the real folders."""
    ws.mkdir(parents=True, exist_ok=True)
    info = '{"codebase_version": "v3.0", "fps": 10, "features": {}, "total_episodes": 0}'
    marker = '{"kind": "%s", "made_by": "pilworld", "settings": {}}'
    folders = {
        "coll": {"meta/info.json": info},  # an unmarked episode store, as sim collect made before markers
        "paired": {"meta/info.json": info, "paired_config.json": "{}", "starts/starts.json": "{}",
                   "starts/meta/info.json": info},
        "starts": {"meta/info.json": info, "starts.json": "{}"},
        "imag": {"meta/info.json": info, "imagine_config.json": "{}"},
        "conv": {"meta/info.json": info, "conversion.json": marker % "converted dataset"},
    }  # fmt: skip
    for name, files in folders.items():
        for rel, text in files.items():
            (ws / name / rel).parent.mkdir(parents=True, exist_ok=True)
            (ws / name / rel).write_text(text)
    _damaged_inputs(ws)
    return ws


if __name__ == "__main__":  # pragma: no cover
    if sys.argv[1:] == ["--serve"]:
        _serve()
