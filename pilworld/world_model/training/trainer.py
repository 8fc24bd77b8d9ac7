"""``pilworld train``: stage 1 pre-trains on all tasks, stage 2 fine-tunes one target task with LoRA.

Stage 1 (``pretrain``) has two phases in one run folder: ``vae`` (the frame autoencoder on frames of
every view) and ``denoiser`` (Ψ_θ by flow matching on cached latents, VAE frozen). Stage 2
(``finetune``) starts from a stage-1 model folder, inserts LoRA adapters (peft) and trains only
them on the target task's clips with a configurable success/failure mix.

A run folder holds ``train_config.json``, ``log.jsonl`` (one line per step; the training curve),
``checkpoints/`` (kept for exact resume), ``latents/`` (the frozen VAE's encodings) and ``model/``
(the result: config + safetensors; stage 2 adds ``adapters/<task>/``). Rerunning the same command
resumes from the last checkpoint and continues with the same data order.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import torch
from safetensors.torch import save_file
from torch import nn
from tqdm import tqdm

from pilworld.config.rig import RigConfig
from pilworld.io.atomic import write_json
from pilworld.world_model.latent.checkpoint import load_model, save_model
from pilworld.world_model.latent.config import ConditioningConfig, preset
from pilworld.world_model.latent.model import PilWorldModel
from pilworld.world_model.latent.vae import to_unit
from pilworld.world_model.training.data import DataSelection, TrainData, step_generator
from pilworld.world_model.training.distributed import Dist, init_distributed, shutdown
from pilworld.world_model.training.state import EMA, latest_checkpoint, load_checkpoint, save_checkpoint

# Debug hook for the DDP tests (see Trainer._dump_rank_weights).
DUMP_RANK_WEIGHTS_ENV = "PILWORLD_DUMP_RANK_WEIGHTS"


@dataclass(frozen=True)
class TrainConfig:
    """Every knob of a training run (stored in ``train_config.json``; a resumed run must match it)."""

    stage: str  # "pretrain" | "finetune"
    data: str  # dataset folder (LeRobot v3.0 layout)
    out: str  # run folder
    rig: str  # rig config (Γ needs its kinematics and head camera)
    preset: str = "small"
    size: tuple[int, int] | None = None  # (width, height) replacing the preset's image size; None = the preset's
    init: str | None = None  # finetune: the stage-1 model folder
    tasks: tuple[str, ...] = ()  # pretrain: all when empty; finetune: the target task
    success_fraction: float | None = None  # share of clips from successful episodes (1.0 = success-only)
    window: int = 9  # clip window W (the paper's 9 stride-sampled frames)
    val_every_episode: int = 20  # every n-th episode is validation
    history: bool = True  # ablation switches (see WorldModelConfig.conditioning)
    control_video: bool = True
    action_tokens: bool = False
    vae_steps: int = 2000
    vae_batch: int = 32
    vae_lr: float = 1e-3
    steps: int = 4000
    batch: int = 16
    lr: float = 3e-4
    warmup: int = 200
    weight_decay: float = 0.01
    grad_clip: float = 1.0
    ema: float = 0.999
    lora_rank: int = 16
    checkpoint_every: int = 250
    validate_every: int = 500
    val_clips: int = 24
    seed: int = 0

    def __post_init__(self) -> None:
        if self.stage not in ("pretrain", "finetune"):
            raise ValueError(f"stage: expected 'pretrain' or 'finetune', got {self.stage!r}")
        if self.stage == "finetune" and not self.init:
            raise ValueError("init: stage 2 (finetune) needs the stage-1 model folder (--init)")
        if self.stage == "finetune" and len(self.tasks) != 1:
            raise ValueError(f"tasks: stage 2 fine-tunes exactly one target task, got {list(self.tasks)}")
        for name in ("steps", "batch", "vae_batch", "checkpoint_every", "validate_every", "window"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name}: expected an integer >= 1, got {v!r}")
        if self.vae_steps < 0 or self.warmup < 0:
            raise ValueError("vae_steps and warmup: expected >= 0")
        if self.size is not None and (len(self.size) != 2 or any(int(v) < 1 for v in self.size)):
            raise ValueError(f"size: expected (width, height) >= 1, got {self.size!r}")
        if self.success_fraction is not None and not 0.0 <= self.success_fraction <= 1.0:
            raise ValueError(f"success_fraction: expected a value in [0, 1], got {self.success_fraction!r}")

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def _lr(step: int, base: float, warmup: int, total: int) -> float:
    """Linear warm-up then cosine decay to 10 % (a pure function of the step, so resume needs no state)."""
    if step < warmup:
        return base * (step + 1) / warmup
    progress = (step - warmup) / max(1, total - warmup)
    return base * (0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi * min(1.0, progress))))


class _Objective(nn.Module):
    """Wraps one phase's loss so DistributedDataParallel sees a forward()."""

    def __init__(self, model: PilWorldModel, fn: Callable[..., tuple[torch.Tensor, dict[str, float]]]) -> None:
        super().__init__()
        self.model = model
        self.fn = fn

    def forward(self, *args: Any, **kwargs: Any) -> tuple[torch.Tensor, dict[str, float]]:
        return self.fn(*args, **kwargs)


class Trainer:
    def __init__(self, config: TrainConfig, *, progress: bool = True, stop_after: int | None = None) -> None:
        self.cfg = config
        self.out = Path(config.out)
        self.progress = progress
        self.stop_after = stop_after  # stop (as if killed) after this many steps of the current phase
        self.dist: Dist = init_distributed()
        for name in ("batch", "vae_batch"):
            if getattr(config, name) < self.dist.world:
                raise ValueError(
                    f"{name}: {getattr(config, name)} is smaller than the {self.dist.world} processes; "
                    "every process needs at least one sample per step"
                )
        self.rig = RigConfig.load(config.rig)

    # ------------------------------------------------------------------ set-up

    def _check_run_folder(self) -> None:
        path = self.out / "train_config.json"
        # Compare in JSON form: the stored file has lists where the config has tuples (e.g. ``tasks``),
        # and () != [] would reject every resume.
        want = json.loads(json.dumps(self.cfg.to_json()))
        if path.is_file():
            have = json.loads(path.read_text())
            # Schedule-only settings may change on resume (e.g. more steps); anything else changes the model.
            free = {"out", "steps", "checkpoint_every", "validate_every", "val_clips"}
            diff = sorted(k for k in set(have) | set(want) if have.get(k) != want.get(k) and k not in free)
            if diff:
                raise ValueError(
                    f"{self.out}: holds a run with different settings ({', '.join(diff)}); "
                    "use a new --out folder or the same arguments to resume"
                )
        if self.dist.main:
            self.out.mkdir(parents=True, exist_ok=True)
            write_json(path, want)
        self.dist.barrier()

    def _log(self, record: dict[str, Any]) -> None:
        if self.dist.main:
            with (self.out / "log.jsonl").open("a") as fh:
                fh.write(json.dumps(record) + "\n")

    def _truncate_log(self, phase: str, step: int) -> None:
        """Drop log lines past the resumed step (they were written after the checkpoint and will be redone)."""
        path = self.out / "log.jsonl"
        if not self.dist.main or not path.is_file():
            return
        keep = []
        for line in path.read_text().splitlines():
            rec = json.loads(line)
            if not (rec.get("phase") == phase and rec.get("step", -1) >= step):
                keep.append(line)
        path.write_text("".join(k + "\n" for k in keep))

    def _model(self) -> PilWorldModel:
        c = self.cfg
        if c.stage == "finetune":
            assert c.init is not None
            return load_model(c.init).train()
        base = preset(c.preset) if c.size is None else preset(c.preset, width=c.size[0], height=c.size[1])
        cond = replace(
            base.conditioning, history=c.history, control_video=c.control_video, action_tokens=c.action_tokens
        )
        # The initial weights come from ``seed`` (they used the global torch RNG: ``--seed`` did not reach
        # them, and a second run in the same process, or a rerun after a kill before the first checkpoint,
        # started from other weights than the first run). A forked RNG leaves the caller's RNG untouched.
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(c.seed)
            return PilWorldModel(base.replace(conditioning=ConditioningConfig(**asdict(cond))))

    # ------------------------------------------------------------------ the generic loop

    def _run_phase(
        self,
        phase: str,
        model: PilWorldModel,
        params: dict[str, nn.Parameter],
        steps: int,
        lr: float,
        loss_fn: Callable[[int], tuple[torch.Tensor, dict[str, float]]],
        on_validate: Callable[[EMA], dict[str, Any]] | None = None,
    ) -> EMA:
        c = self.cfg
        names = {id(p): n for n, p in params.items()}
        opt = torch.optim.AdamW(list(params.values()), lr=lr, weight_decay=c.weight_decay, betas=(0.9, 0.99))
        ema = EMA(params, c.ema)
        ckpt_root = self.out / "checkpoints"
        start = 0
        resume = latest_checkpoint(ckpt_root, phase)
        if resume is not None:
            load_checkpoint(resume, model, opt, names, ema)
            start = resume.step
            self._truncate_log(phase, start)
        if start >= steps:
            return ema
        bar = tqdm(total=steps, initial=start, desc=phase, unit="step", disable=not (self.progress and self.dist.main))
        for done_here, step in enumerate(range(start, steps), start=1):
            for g in opt.param_groups:
                g["lr"] = _lr(step, lr, min(c.warmup, steps // 10), steps)
            t0 = time.perf_counter()
            loss, logs = loss_fn(step)
            opt.zero_grad(set_to_none=True)
            loss.backward()  # type: ignore[no-untyped-call]
            grad_norm = torch.nn.utils.clip_grad_norm_(list(params.values()), c.grad_clip)
            opt.step()
            ema.update(params, step)
            record = {"phase": phase, "step": step, "lr": opt.param_groups[0]["lr"], "grad_norm": float(grad_norm)}
            record.update(logs)
            record["seconds"] = round(time.perf_counter() - t0, 4)
            if on_validate is not None and ((step + 1) % c.validate_every == 0 or step + 1 == steps):
                record["val"] = on_validate(ema)
            self._log(record)
            bar.set_postfix(loss=f"{logs['loss']:.4f}")
            bar.update(1)
            finished = step + 1 == steps
            if self.dist.main and ((step + 1) % c.checkpoint_every == 0 or finished):
                save_checkpoint(ckpt_root, phase, step + 1, model, opt, names, ema, {"seed": c.seed})
            self.dist.barrier()
            if self.stop_after is not None and done_here >= self.stop_after and not finished:
                bar.close()
                raise InterruptedError(f"stopped after {done_here} steps of {phase} (as asked)")
        bar.close()
        return ema

    # ------------------------------------------------------------------ stages

    def run(self) -> Path:
        try:
            # Build the model first: a bad preset, ablation mix or --init then fails before the run folder
            # records the settings (which would make the corrected command a "run with different settings").
            model = self._model()
            self._check_run_folder()
            model.to(self.dist.device())
            final = self._pretrain(model) if self.cfg.stage == "pretrain" else self._finetune(model)
            self._dump_rank_weights(model)
            return final
        finally:
            shutdown(self.dist)

    def _dump_rank_weights(self, model: PilWorldModel) -> None:
        """Debug hook: with ``$PILWORLD_DUMP_RANK_WEIGHTS=DIR`` set, every rank writes its final model state
        (the raw weights, not the EMA) to ``DIR/rank{r}.safetensors``, so a test can check that DDP kept
        the ranks bit-identical. Off (and free) when the variable is unset."""
        folder = os.environ.get(DUMP_RANK_WEIGHTS_ENV)
        if not folder:
            return
        Path(folder).mkdir(parents=True, exist_ok=True)
        state = {k: v.detach().contiguous().cpu() for k, v in model.state_dict().items()}
        save_file(state, str(Path(folder) / f"rank{self.dist.rank}.safetensors"))

    def _data(self, model: PilWorldModel) -> TrainData:
        c = self.cfg
        sel = DataSelection(c.tasks, c.success_fraction, c.val_every_episode, c.window)
        return TrainData(c.data, self.rig, model, sel)

    def _pretrain(self, model: PilWorldModel) -> Path:
        c, d = self.cfg, self.dist
        data = self._data(model)
        if c.vae_steps > 0:
            for p in model.parameters():
                p.requires_grad_(False)
            vae_params = {f"vae.{n}": p for n, p in model.vae.named_parameters()}
            for p in vae_params.values():
                p.requires_grad_(True)
            objective = self._wrap(model, lambda x, g: model.vae.loss(x, g))

            def vae_loss(step: int) -> tuple[torch.Tensor, dict[str, float]]:
                x = data.frame_batch(c.seed, step, c.vae_batch, d.rank, d.world).to(d.device())
                out: tuple[torch.Tensor, dict[str, float]] = objective(
                    to_unit(x), step_generator(c.seed, step, d.rank, 2)
                )
                return out

            # The VAE is used as trained, not its EMA (the EMA lags behind a short run's sharpest decoder).
            self._run_phase("vae", model, vae_params, c.vae_steps, c.vae_lr, vae_loss)
        self._prepare_latents(model, data)
        return self._train_denoiser(model, data, lora=False)

    def _prepare_latents(self, model: PilWorldModel, data: TrainData) -> None:
        c, d = self.cfg, self.dist
        stats_path = self.out / "latent_stats.json"
        if d.main and not stats_path.is_file():
            mean, std = data.latent_stats(c.seed)
            write_json(stats_path, {"mean": mean, "std": std})
        d.barrier()
        stats = json.loads(stats_path.read_text())
        if self.cfg.stage == "pretrain":
            model.set_latent_stats(stats["mean"], stats["std"])
        if d.main:
            data.build_latents(self.out / "latents", progress=self.progress)
        d.barrier()
        if not d.main:
            data.build_latents(self.out / "latents", progress=False)

    def _finetune(self, model: PilWorldModel) -> Path:
        data = self._data(model)
        self._prepare_latents(model, data)
        return self._train_denoiser(model, data, lora=True)

    def _wrap(self, model: PilWorldModel, fn: Callable[..., tuple[torch.Tensor, dict[str, float]]]) -> nn.Module:
        obj = _Objective(model, fn)
        if self.dist.enabled:
            from torch.nn.parallel import DistributedDataParallel

            return DistributedDataParallel(obj, find_unused_parameters=False)
        return obj

    def _train_denoiser(self, model: PilWorldModel, data: TrainData, *, lora: bool) -> Path:
        from pilworld.world_model.latent.lora import add_lora, save_adapter

        c, d = self.cfg, self.dist
        for p in model.parameters():
            p.requires_grad_(False)
        if lora:
            add_lora(model, c.lora_rank)
            params = {n: p for n, p in model.named_parameters() if "lora_" in n}
        else:
            params = {f"denoiser.{n}": p for n, p in model.denoiser.named_parameters()}
        for p in params.values():
            p.requires_grad_(True)
        objective = self._wrap(model, model.flow_loss)
        val = data.val_batch(c.val_clips, c.seed) if d.main else None

        def loss(step: int) -> tuple[torch.Tensor, dict[str, float]]:
            b = data.latent_batch(data.clip_indices(c.seed, step, c.batch, d.rank, d.world))
            dev = d.device()
            out: tuple[torch.Tensor, dict[str, float]] = objective(
                b.future.to(dev),
                b.current.to(dev),
                b.history.to(dev),
                b.history_valid.to(dev),
                b.control.to(dev),
                b.actions.to(dev),
                b.instruction,
                step_generator(c.seed, step, d.rank, 3),
            )
            return out

        def validate(ema: EMA) -> dict[str, Any]:
            if val is None:
                return {}
            with Swapped(params, ema.shadow):
                return validation_scores(model, val)

        phase = "lora" if lora else "denoiser"
        ema = self._run_phase(phase, model, params, c.steps, c.lr, loss, validate)
        final = self.out / "model"
        if d.main:
            with Swapped(params, ema.shadow):
                if lora:
                    assert c.init is not None
                    if not (final / "model.safetensors").is_file():
                        shutil.copytree(c.init, final, dirs_exist_ok=True, ignore=shutil.ignore_patterns("adapters"))
                    save_adapter(model, final / "adapters" / c.tasks[0], c.lora_rank)
                else:
                    save_model(model, final)
                scores = validation_scores(model, val)
            write_json(self.out / "final_validation.json", scores)
        d.barrier()
        return final


class Swapped:
    """Context manager: temporarily load ``weights`` (e.g. the EMA) into ``params``."""

    def __init__(self, params: dict[str, nn.Parameter], weights: dict[str, torch.Tensor]) -> None:
        self.params, self.weights = params, weights
        self.saved: dict[str, torch.Tensor] = {}

    def __enter__(self) -> None:
        with torch.no_grad():
            for k, p in self.params.items():
                self.saved[k] = p.detach().clone()
                p.copy_(self.weights[k])

    def __exit__(self, *exc: object) -> None:
        with torch.no_grad():
            for k, p in self.params.items():
                p.copy_(self.saved[k])


def validation_scores(model: PilWorldModel, batch: Any) -> dict[str, Any]:
    """Per view: pooled PSNR (of the mean squared error over all validation frames), mean SSIM, and the
    frozen baseline's pooled PSNR, for the model's predictions at its default sampling steps.

    Pooled, not the mean of per-frame PSNRs: a still camera renders bit-identical frames that the frozen
    baseline copies exactly, and each would score the PSNR cap (see pilworld.world_model.metrics).
    """
    from pilworld.world_model.metrics import mse, psnr_from_mse, ssim

    was_training = model.training
    model.eval()
    pred = model.predict_batch(batch, seed=0)
    model.train(was_training)
    assert batch.future is not None
    out: dict[str, Any] = {}
    for i, v in enumerate(model.config.views):
        p, t = pred[:, i], batch.future[:, i]
        frozen = batch.current[:, i, None].expand_as(t)
        out[v] = {
            "psnr_pooled": float(psnr_from_mse(mse(p, t).mean())),
            "ssim": float(ssim(p, t).mean()),
            "psnr_pooled_frozen": float(psnr_from_mse(mse(frozen, t).mean())),
        }
    return out
