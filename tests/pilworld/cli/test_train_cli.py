"""``pilworld train pretrain|finetune`` through ``main`` on the tiny synthetic dataset (preset ``tiny``)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from pilworld.cli.main import main
from pilworld.world_model.loader import load_world_model
from tests.pilworld.world_model.training.synthetic_data import SIM_RIG, write_dataset


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_dataset(tmp_path_factory.mktemp("train_cli") / "ds")


@pytest.fixture(autouse=True)
def clip_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PILWORLD_CACHE", str(tmp_path / "cache"))


def _pretrain(data: Path, out: Path, *extra: str) -> list[str]:
    return [
        "train", "pretrain", "--data", str(data), "--out", str(out), "--rig", str(SIM_RIG), "--preset", "tiny",
        "--vae-steps", "2", "--steps", "2", "--batch", "2", "--window", "3", "--val-clips", "2", "--quiet", *extra,
    ]  # fmt: skip


def test_pretrain_then_finetune(dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    assert main(_pretrain(dataset, out)) == 0
    assert f"model: {out / 'model'}" in capsys.readouterr().out
    assert [json.loads(line)["phase"] for line in (out / "log.jsonl").read_text().splitlines()] == ["vae"] * 2 + [
        "denoiser"
    ] * 2
    load_world_model(out / "model")
    # Rerunning the same command resumes a finished run: nothing more to train, still exit 0.
    assert main(_pretrain(dataset, out)) == 0
    assert len((out / "log.jsonl").read_text().splitlines()) == 4

    ft = tmp_path / "ft"
    args = ["train", "finetune", "--data", str(dataset), "--out", str(ft), "--rig", str(SIM_RIG)]
    args += ["--init", str(out / "model"), "--task", "taskB", "--lora-rank", "2", "--steps", "2", "--batch", "2"]
    args += ["--window", "3", "--success-fraction", "0.5", "--val-clips", "2", "--quiet"]
    assert main(args) == 0
    assert (ft / "model" / "adapters" / "taskB" / "adapter.safetensors").is_file()
    config = json.loads((ft / "train_config.json").read_text())
    assert config["tasks"] == ["taskB"] and config["lr"] == pytest.approx(1e-3)  # LoRA's default rate
    load_world_model(ft / "model", adapter="taskB")


def test_bad_preset_exits_2(dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    argv = _pretrain(dataset, out)
    argv[argv.index("tiny")] = "huge"
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "pilworld: error: preset: unknown 'huge'; known presets: ['base', 'small', 'tiny']" in err
    assert not out.exists()  # nothing recorded, so the corrected command may use the same --out


def test_user_errors_exit_2(dataset: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(_pretrain(dataset, tmp_path / "a", "--no-control-video")) == 2
    assert "needs the control video, action tokens, or both" in capsys.readouterr().err
    assert main(_pretrain(tmp_path / "missing", tmp_path / "b")) == 2
    assert "not a LeRobot dataset (no meta/info.json)" in capsys.readouterr().err
    argv = ["train", "finetune", "--data", str(dataset), "--out", str(tmp_path / "c"), "--init", str(tmp_path / "x")]
    assert main([*argv, "--task", "taskA", "--steps", "0"]) == 2
    assert "--steps: expected an integer in 1..10,000,000, got 0" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:  # argparse: a missing required option
        main(["train", "finetune", "--data", str(dataset), "--out", str(tmp_path / "d")])
    assert exc.value.code == 2


@pytest.mark.parametrize("spelling", [["--nproc", "2"], ["--nproc=2"]])
def test_nproc_relaunches_under_torchrun(spelling: list[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[tuple[list[str], dict[str, str]]] = []

    def fake_call(cmd: list[str], env: dict[str, str], **kwargs: Any) -> int:
        calls.append((cmd, env))
        return 0

    monkeypatch.setattr(subprocess, "call", fake_call)
    monkeypatch.delenv("WORLD_SIZE", raising=False)
    argv = ["train", "pretrain", "--data", str(tmp_path), "--out", str(tmp_path / "o"), *spelling, "--preset", "tiny"]
    monkeypatch.setattr(sys, "argv", ["pilworld", *argv])
    assert main(argv) == 0
    ((cmd, env),) = calls
    assert cmd[:5] == [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node=2"]
    assert cmd[5:7] == ["-m", "pilworld"] and cmd[7:] == argv
    assert env["OMP_NUM_THREADS"] == os.environ.get("OMP_NUM_THREADS", "1")


def test_train_plot_writes_the_curve(tmp_path: Path) -> None:
    from pilworld.cli.main import main

    run = tmp_path / "run"
    run.mkdir()
    lines: list[dict[str, object]] = [
        {"phase": "vae", "step": i, "loss": 1.0 / (i + 1), "psnr": 10.0 + i} for i in range(30)
    ]
    val = {"cam_high": {"psnr": 25.0, "ssim": 0.9, "psnr_frozen": 22.0}}
    lines += [
        {"phase": "denoiser", "step": i, "loss": 1.0 / (i + 1), **({"val": val} if i % 10 == 9 else {})}
        for i in range(60)
    ]
    (run / "log.jsonl").write_text("".join(json.dumps(r) + "\n" for r in lines))
    out = tmp_path / "curve.png"
    assert main(["train", "plot", str(run), "--out", str(out)]) == 0
    pooled = {"cam_high": {"psnr_pooled": 21.0, "ssim": 0.9, "psnr_pooled_frozen": 18.0}}
    (run / "log.jsonl").write_text(json.dumps({"phase": "denoiser", "step": 0, "loss": 1.0, "val": pooled}) + "\n")
    assert main(["train", "plot", str(run), "--out", str(out)]) == 0
    assert out.stat().st_size > 10_000 and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["train", "plot", str(tmp_path / "missing"), "--out", str(out)]) == 2
