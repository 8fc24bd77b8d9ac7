"""``pilworld train`` end to end on a tiny synthetic dataset (preset ``tiny``): stage 1, exact resume
(in process and after SIGKILL), stage 2 LoRA, the data order, and DDP under torchrun."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from safetensors.torch import load_file

from pilworld.config.rig import RigConfig
from pilworld.world_model.latent.config import preset
from pilworld.world_model.latent.model import PilWorldModel
from pilworld.world_model.loader import load_world_model
from pilworld.world_model.training.data import DataSelection, TrainData, is_validation_episode
from pilworld.world_model.training.trainer import DUMP_RANK_WEIGHTS_ENV, TrainConfig, Trainer

from .synthetic_data import EPISODES, INSTRUCTIONS, ROOT, SIM_RIG, success_of, task_of

VAE_STEPS, STEPS = 4, 6


def pretrain_config(data: Path, out: Path, **changes: Any) -> TrainConfig:
    cfg = TrainConfig(
        stage="pretrain",
        data=str(data),
        out=str(out),
        rig=str(SIM_RIG),
        preset="tiny",
        vae_steps=VAE_STEPS,
        vae_batch=4,
        steps=STEPS,
        batch=2,
        window=3,
        checkpoint_every=2,
        validate_every=3,
        val_clips=2,
        val_every_episode=3,
    )
    return dataclasses.replace(cfg, **changes)


def finetune_config(data: Path, out: Path, init: Path | None, **changes: Any) -> TrainConfig:
    cfg = TrainConfig(
        stage="finetune",
        data=str(data),
        out=str(out),
        rig=str(SIM_RIG),
        preset="",
        init=None if init is None else str(init),
        tasks=("taskA",),
        success_fraction=0.5,
        lora_rank=2,
        lr=1e-3,
        steps=4,
        batch=2,
        window=3,
        checkpoint_every=2,
        validate_every=3,
        val_clips=2,
        val_every_episode=3,
    )
    return dataclasses.replace(cfg, **changes)


def read_log(run: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in (run / "log.jsonl").read_text().splitlines()]


def curve(run: Path) -> list[tuple[Any, ...]]:
    """What must match between two runs of the same config: every step's phase, losses, lr and val scores."""
    keys = ("phase", "step", "lr", "loss", "grad_norm", "x0_mse", "psnr", "val")
    return [tuple(r.get(k) for k in keys) for r in read_log(run)]


def assert_same_weights(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> None:
    assert a.keys() == b.keys()
    different = [k for k in a if not torch.equal(a[k], b[k])]
    assert not different, f"tensors differ: {different[:5]}"


def assert_same_run(a: Path, b: Path) -> None:
    assert_same_weights(load_file(a / "model" / "model.safetensors"), load_file(b / "model" / "model.safetensors"))
    assert curve(a) == curve(b)
    for name in ("latent_stats.json", "final_validation.json"):
        assert json.loads((a / name).read_text()) == json.loads((b / name).read_text()), name


def example_batch(model: PilWorldModel) -> Any:
    from pilworld.world_model.base import PredictRequest

    info = model.info
    rng = np.random.default_rng(0)
    return PredictRequest.build(
        info,
        current={v: rng.integers(0, 256, (32, 32, 3), dtype=np.uint8) for v in info.views},
        history=None,
        control=rng.integers(0, 256, (info.future, 32, 32, 3), dtype=np.uint8),
        actions=np.zeros((info.future, info.action_dim)),
        instruction=INSTRUCTIONS["taskA"],
    ).to_batch(info.views)


@pytest.fixture(scope="module")
def pretrained(dataset: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An uninterrupted stage-1 run (run A of the resume tests)."""
    out = tmp_path_factory.mktemp("pretrain") / "run"
    Trainer(pretrain_config(dataset, out), progress=False).run()
    return out


@pytest.fixture(scope="module")
def finetuned(dataset: Path, pretrained: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("finetune") / "run"
    Trainer(finetune_config(dataset, out, pretrained / "model"), progress=False).run()
    return out


# ---------------------------------------------------------------------- stage 1


def test_pretrain_end_to_end(pretrained: Path) -> None:
    model_dir = pretrained / "model"
    assert (model_dir / "config.json").is_file() and (model_dir / "model.safetensors").is_file()
    log = read_log(pretrained)
    # One line per step per phase, in order.
    assert [(r["phase"], r["step"]) for r in log] == [("vae", s) for s in range(VAE_STEPS)] + [
        ("denoiser", s) for s in range(STEPS)
    ]
    assert all(np.isfinite(r["loss"]) and np.isfinite(r["grad_norm"]) for r in log)
    # Validation every 3 denoiser steps (and at the last), with per-view PSNR/SSIM.
    assert [r["step"] for r in log if "val" in r] == [2, 5]
    final = json.loads((pretrained / "final_validation.json").read_text())
    assert set(final) == {"cam_high", "cam_left_wrist", "cam_right_wrist"}
    for scores in final.values():
        assert np.isfinite(scores["psnr_pooled"]) and -1.0 <= scores["ssim"] <= 1.0
        assert np.isfinite(scores["psnr_pooled_frozen"])
    # The VAE's latent statistics went into the saved config; latents were cached per (episode, view).
    stats = json.loads((pretrained / "latent_stats.json").read_text())
    model = load_world_model(model_dir)
    assert model.config.preset == "tiny" and model.config.latent_mean == pytest.approx(stats["mean"])
    assert len(list((pretrained / "latents").glob("*.npy"))) == EPISODES * 3
    # At most two checkpoints per phase are kept.
    names = sorted(p.name for p in (pretrained / "checkpoints").iterdir())
    assert names == ["denoiser-0000004", "denoiser-0000006", "vae-0000002", "vae-0000004"]
    out = model.predict_batch(example_batch(model))
    assert out.dtype == torch.uint8 and tuple(out.shape) == (1, 3, 15, 3, 32, 32)


def test_exact_resume_in_process(dataset: Path, pretrained: Path, tmp_path: Path) -> None:
    run = tmp_path / "B"
    cfg = pretrain_config(dataset, run)
    # Killed in the VAE phase (after 3 of 4 steps; the last checkpoint is at step 2) ...
    with pytest.raises(InterruptedError, match="stopped after 3 steps of vae"):
        Trainer(cfg, progress=False, stop_after=3).run()
    assert [r["step"] for r in read_log(run)] == [0, 1, 2]
    assert not (run / "model").exists()
    # ... then in the denoiser phase (after 5 of 6 steps; the last checkpoint is at step 4) ...
    with pytest.raises(InterruptedError, match="stopped after 5 steps of denoiser"):
        Trainer(cfg, progress=False, stop_after=5).run()
    # ... and finished: bit-identical to the uninterrupted run A, with each step logged once.
    Trainer(cfg, progress=False).run()
    assert_same_run(pretrained, run)
    # Rerunning a finished run (schedule-only settings may change) trains nothing and changes nothing.
    before = (run / "log.jsonl").read_text()
    Trainer(dataclasses.replace(cfg, checkpoint_every=3), progress=False).run()
    assert (run / "log.jsonl").read_text() == before
    assert_same_run(pretrained, run)


def test_resume_with_a_different_model_setting_is_refused(dataset: Path, pretrained: Path) -> None:
    before = (pretrained / "train_config.json").read_text()
    with pytest.raises(ValueError, match=r"different settings \(history\)"):
        Trainer(pretrain_config(dataset, pretrained, history=False), progress=False).run()
    with pytest.raises(ValueError, match=r"different settings \(lr, window\)"):
        Trainer(pretrain_config(dataset, pretrained, window=4, lr=1e-3), progress=False).run()
    assert (pretrained / "train_config.json").read_text() == before


def test_invalid_settings_leave_no_run_folder(dataset: Path, tmp_path: Path) -> None:
    # Checked before train_config.json is written, so the corrected command can use the same folder.
    with pytest.raises(ValueError, match=r"preset: unknown 'huge'"):
        Trainer(pretrain_config(dataset, tmp_path / "p", preset="huge"), progress=False).run()
    with pytest.raises(ValueError, match="needs the control video, action tokens, or both"):
        Trainer(pretrain_config(dataset, tmp_path / "c", control_video=False), progress=False).run()
    with pytest.raises(FileNotFoundError, match="no world-model config"):
        Trainer(finetune_config(dataset, tmp_path / "f", tmp_path / "nowhere"), progress=False).run()
    assert not any((tmp_path / n).exists() for n in ("p", "c", "f"))


def test_seed_sets_the_initial_weights(dataset: Path, tmp_path: Path) -> None:
    def initial(seed: int) -> dict[str, torch.Tensor]:
        return Trainer(pretrain_config(dataset, tmp_path, seed=seed), progress=False)._model().state_dict()

    first = initial(0)
    torch.rand(3)  # the global RNG's state does not matter
    assert_same_weights(first, initial(0))
    assert not torch.equal(first["denoiser.pos"], initial(1)["denoiser.pos"])


@pytest.mark.slow
def test_exact_resume_after_sigkill(dataset: Path, clip_cache: Path, tmp_path: Path) -> None:
    """``pilworld train pretrain`` killed with SIGKILL at its first denoiser checkpoint, then rerun,
    ends bit-identical to an uninterrupted run of the same command."""
    env = dict(os.environ, OMP_NUM_THREADS="1", PILWORLD_CACHE=str(clip_cache))

    def command(out: Path) -> list[str]:
        return [
            sys.executable, "-m", "pilworld", "train", "pretrain", "--data", str(dataset), "--out", str(out),
            "--rig", str(SIM_RIG), "--preset", "tiny", "--vae-steps", "30", "--steps", "40", "--batch", "2",
            "--window", "3", "--checkpoint-every", "5", "--validate-every", "20", "--val-clips", "2", "--quiet",
        ]  # fmt: skip

    whole, killed = tmp_path / "whole", tmp_path / "killed"
    subprocess.run(command(whole), env=env, cwd=ROOT, check=True, timeout=600, capture_output=True)
    proc = subprocess.Popen(command(killed), env=env, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 300
        while not list((killed / "checkpoints").glob("denoiser-*")) and proc.poll() is None:
            assert time.monotonic() < deadline, "no denoiser checkpoint appeared"
            time.sleep(0.01)
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait(timeout=60)
    assert proc.returncode == -signal.SIGKILL, "the run finished before it could be killed"
    assert not (killed / "model").exists()
    subprocess.run(command(killed), env=env, cwd=ROOT, check=True, timeout=600, capture_output=True)
    assert_same_run(whole, killed)


# ---------------------------------------------------------------------- stage 2


def test_finetune_trains_only_the_adapter(pretrained: Path, finetuned: Path) -> None:
    model_dir = finetuned / "model"
    adapter = model_dir / "adapters" / "taskA"
    assert (adapter / "adapter.safetensors").is_file() and (adapter / "adapter_config.json").is_file()
    assert json.loads((adapter / "adapter_config.json").read_text())["r"] == 2
    assert [(r["phase"], r["step"]) for r in read_log(finetuned)] == [("lora", s) for s in range(4)]
    base = load_file(pretrained / "model" / "model.safetensors")
    # The finetune model folder carries the stage-1 weights unchanged ...
    assert_same_weights(base, load_file(model_dir / "model.safetensors"))
    # ... and so does the trained model of its last checkpoint: only LoRA weights moved.
    trained = load_file(finetuned / "checkpoints" / "lora-0000004" / "model.safetensors")
    lora = {k: v for k, v in trained.items() if "lora_" in k}
    assert lora and all(k.startswith("denoiser.blocks.") for k in lora)
    assert_same_weights(base, {k.replace("base_layer.", ""): v for k, v in trained.items() if "lora_" not in k})
    assert any(v.abs().max() > 0 for k, v in lora.items() if "lora_B" in k)  # B starts at zero: it trained
    # The adapter loads (merged) and the merged model predicts.
    merged = load_world_model(model_dir, adapter="taskA")
    out = merged.predict_batch(example_batch(merged))
    assert out.dtype == torch.uint8 and tuple(out.shape) == (1, 3, 15, 3, 32, 32)
    assert json.loads((finetuned / "final_validation.json").read_text()).keys() == {
        "cam_high",
        "cam_left_wrist",
        "cam_right_wrist",
    }


def test_finetune_errors(dataset: Path, pretrained: Path, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"tasks: \['nope'\] not in .*has \['taskA', 'taskB'\]"):
        Trainer(finetune_config(dataset, tmp_path / "x", pretrained / "model", tasks=("nope",)), progress=False).run()
    with pytest.raises(ValueError, match=r"init: stage 2 .* needs the stage-1 model folder"):
        finetune_config(dataset, tmp_path / "y", None)
    with pytest.raises(ValueError, match="exactly one target task"):
        finetune_config(dataset, tmp_path / "z", pretrained / "model", tasks=("taskA", "taskB"))
    with pytest.raises(ValueError, match="success_fraction"):
        finetune_config(dataset, tmp_path / "z", pretrained / "model", success_fraction=1.5)


# ---------------------------------------------------------------------- data order


@pytest.fixture(scope="module")
def train_data(dataset: Path) -> TrainData:
    model = PilWorldModel(preset("tiny"))
    return TrainData(dataset, RigConfig.load(SIM_RIG), model, DataSelection(window=3, val_every=3))


def test_clip_selection(train_data: TrainData) -> None:
    clips = train_data.dataset.clips
    assert train_data.dataset.spec.stride == 1  # stored at the stride (steps_per_frame = 3)
    assert len(clips) == EPISODES * 9  # 40 frames: starts 0, 3, …, 24
    train_eps = {clips[i].episode_index for i in train_data.train_clips}
    val_eps = {clips[i].episode_index for i in train_data.val_clips}
    assert train_eps == {0, 1, 3, 4} and val_eps == {2, 5}
    assert all(is_validation_episode(e, 3) for e in val_eps)


def test_clip_indices_are_a_pure_function_of_seed_step_rank(train_data: TrainData) -> None:
    a = train_data.clip_indices(seed=0, step=7, batch=8)
    assert np.array_equal(a, train_data.clip_indices(seed=0, step=7, batch=8))
    draws = [train_data.clip_indices(seed=0, step=s, batch=8) for s in range(5)]
    assert len({d.tobytes() for d in draws}) == 5  # steps differ
    assert not np.array_equal(a, train_data.clip_indices(seed=1, step=7, batch=8))
    # Each rank takes its slice of the same global draw: together they are the global batch.
    for world in (2, 4):
        parts = [train_data.clip_indices(0, 7, 8, rank=r, world=world) for r in range(world)]
        assert all(len(p) == 8 // world for p in parts)
        for r, p in enumerate(parts):
            assert np.array_equal(p, a[r::world])
        assert sorted(np.concatenate(parts).tolist()) == sorted(a.tolist())
    # Only training clips are ever drawn.
    drawn = np.concatenate([train_data.clip_indices(0, s, 16) for s in range(40)])
    assert set(drawn.tolist()) <= set(train_data.train_clips.tolist())
    # The VAE's frames follow the same rule.
    assert torch.equal(train_data.frame_batch(0, 3, 6), train_data.frame_batch(0, 3, 6))
    assert torch.equal(train_data.frame_batch(0, 3, 6, rank=1, world=2), train_data.frame_batch(0, 3, 6)[1::2])


def test_success_fraction(dataset: Path) -> None:
    model = PilWorldModel(preset("tiny"))
    rig = RigConfig.load(SIM_RIG)

    def drawn_episodes(sel: DataSelection) -> list[int]:
        data = TrainData(dataset, rig, model, sel)
        draws = np.concatenate([data.clip_indices(0, s, 16) for s in range(50)])
        return [data.dataset.clips[int(i)].episode_index for i in draws]

    only = drawn_episodes(DataSelection(window=3, val_every=3, success_fraction=1.0))
    assert set(only) == {0, 1} and all(success_of(e) for e in only)
    half = drawn_episodes(DataSelection(window=3, val_every=3, success_fraction=0.5, tasks=("taskA",)))
    assert set(half) == {0, 4}  # taskA's training episodes: a success and a failure
    assert 0.35 < np.mean([success_of(e) for e in half]) < 0.65
    # A task may also be named by its instruction.
    by_instruction = drawn_episodes(DataSelection(window=3, val_every=3, tasks=(INSTRUCTIONS["taskB"],)))
    assert {task_of(e) for e in by_instruction} == {"taskB"}


# ---------------------------------------------------------------------- DDP


def test_torchrun_ddp_keeps_ranks_identical(dataset: Path, clip_cache: Path, tmp_path: Path) -> None:
    out, dump = tmp_path / "ddp", tmp_path / "dump"
    env = dict(os.environ, OMP_NUM_THREADS="1", PILWORLD_CACHE=str(clip_cache), **{DUMP_RANK_WEIGHTS_ENV: str(dump)})
    cmd = [
        sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node=2",
        "-m", "pilworld", "train", "pretrain", "--data", str(dataset), "--out", str(out), "--rig", str(SIM_RIG),
        "--preset", "tiny", "--vae-steps", "2", "--steps", "3", "--batch", "4", "--window", "3",
        "--val-clips", "2", "--quiet",
    ]  # fmt: skip
    proc = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "model:" in proc.stdout  # printed by rank 0 only
    ranks = [load_file(dump / f"rank{r}.safetensors") for r in range(2)]
    assert_same_weights(ranks[0], ranks[1])
    assert (out / "model" / "model.safetensors").is_file()
    assert [(r["phase"], r["step"]) for r in read_log(out)] == [("vae", 0), ("vae", 1)] + [
        ("denoiser", s) for s in range(3)
    ]
    load_world_model(out / "model")
