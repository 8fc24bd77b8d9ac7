"""Training world model v2: ``pilworld train composite --data D --out RUN`` (resumable, exact).

1. The sample cache (:mod:`.cache`): candidate layers and true frames of clips from the dataset,
   at the network's working resolution, built once under ``RUN/cache/``.
2. The U-Net, the robot painter and the grip head, trained together with AdamW and a cosine schedule:
   L1 of the composite against the true frame (×5 where the frame changed from the current one — the
   arm and what it moves — so a still scene cannot dominate), plus L1 of the predicted gripper
   openings against the measured ones. Context noise: with probability ½ the layers made from the
   current frame get Gaussian noise (σ ≤ 0.04) and a slight blur, because in closed loop they are
   made from generated frames.
3. Every ``--checkpoint-every`` steps a checkpoint (safetensors: weights, AdamW moments, EMA; JSON:
   step and settings); rerunning the command resumes from the last one with the same batches (the
   batch of step s is a pure function of (seed, s)). Validation on held-out episodes (every 20th)
   against the static-prior baseline, one JSON line per event in ``RUN/log.jsonl``.
4. ``RUN/model/``: ``config.json`` + ``model.safetensors`` (the EMA weights), loadable by
   :func:`pilworld.world_model.latent.checkpoint.load_world_model`.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.nn import functional as F
from tqdm import tqdm

from pilworld.world_model.composite.cache import CacheSpec, build_cache, build_extras
from pilworld.world_model.composite.model import CompositeConfig, CompositeWorldModel
from pilworld.world_model.composite.switches import Switches
from pilworld.world_model.training.state import EMA, latest_checkpoint, load_checkpoint, save_checkpoint
from simrig.files import SIM_RIG_IN_CHECKOUT

PHASE = "composite"
CHANGED = 0.08  # a target pixel this far (max over channels, in [0, 1]) from the current frame "changed"
CHANGED_WEIGHT = 4.0
GRIP_WEIGHT = 2.0


@dataclass(frozen=True)
class TrainSettings:
    data: str
    rig: str = SIM_RIG_IN_CHECKOUT
    steps: int = 4000
    batch: int = 32
    lr: float = 2e-3
    width: int = 16
    work_size: int = 32  # the U-Net's resolution
    cache_size: int = 64  # the training composite's resolution
    seed: int = 0
    max_clips: int = 3000
    frames_per_clip: int = 5
    context_noise: float = 0.04
    switches: Switches = field(default_factory=Switches)  # a recipe variant (docs/RESULTS.md §1); default: shipped
    success_only: bool = False  # train on clips of successful episodes only (a variant's data switch)

    # settings a resumed run may change (the schedule); any other difference is refused
    @staticmethod
    def schedule_keys() -> tuple[str, ...]:
        return ("steps",)


def _batch_indices(pool: np.ndarray[Any, Any], seed: int, step: int, size: int) -> np.ndarray[Any, Any]:
    rng = np.random.default_rng([seed, step])
    return np.sort(pool[rng.integers(0, len(pool), size)])


# What a run started before these settings existed was trained with (it may resume under them).
_LATER_DEFAULTS = {"switches": Switches().to_dict(), "success_only": False}


def _load(cache: Path, extras: bool = False) -> dict[str, np.ndarray[Any, Any]]:
    names = ("inputs", "targets", "scalars", "grips", "episodes") + (("markers", "actions") if extras else ())
    return {k: np.load(cache / f"{k}.npy", mmap_mode="r") for k in names}


def _tensors(arrs: dict[str, np.ndarray[Any, Any]], idx: np.ndarray[Any, Any]) -> tuple[torch.Tensor, ...]:
    return tuple(
        torch.from_numpy(np.ascontiguousarray(arrs[k][idx])) for k in ("inputs", "targets", "scalars", "grips")
    )


def _extras(
    model: CompositeWorldModel, arrs: dict[str, np.ndarray[Any, Any]], idx: np.ndarray[Any, Any]
) -> dict[str, torch.Tensor]:
    """The variant's extra inputs of these samples (``train_forward``'s keyword arguments)."""
    sw = model.switches
    out: dict[str, torch.Tensor] = {}
    if sw.markers:
        out["markers"] = torch.from_numpy(np.ascontiguousarray(arrs["markers"][idx]))
    if sw.action_tokens:
        out["actions"] = torch.from_numpy(np.ascontiguousarray(arrs["actions"][idx]))
    return out


def _context_noise(base: torch.Tensor, gen: torch.Generator, sigma_max: float) -> torch.Tensor:
    """Noise and a slight blur on the layers made from the current frame (channels 0–14), half the batch."""
    x = base.float()
    n = x.shape[0]
    pick = torch.rand(n, generator=gen) < 0.5
    if not pick.any():
        return base
    img = x[pick, :15] / 255.0
    sigma = torch.rand(int(pick.sum()), 1, 1, 1, generator=gen) * sigma_max
    blurred = F.avg_pool2d(F.pad(img, (1, 1, 1, 1), mode="replicate"), 3, stride=1)
    mix = torch.rand(int(pick.sum()), 1, 1, 1, generator=gen) * 0.5
    img = (1 - mix) * img + mix * blurred + sigma * torch.randn(img.shape, generator=gen)
    # validity channels (3, 10, 14) stay binary
    for c in (3, 10, 14):
        img[:, c] = x[pick, c] / 255.0
    x[pick, :15] = img.clamp(0, 1) * 255.0
    return x.round().to(torch.uint8)


def loss_terms(
    model: CompositeWorldModel,
    base: torch.Tensor,
    target: torch.Tensor,
    scal: torch.Tensor,
    grips: torch.Tensor,
    extras: dict[str, torch.Tensor] | None = None,
) -> tuple[torch.Tensor, dict[str, float]]:
    out, pred_grips = model.train_forward(base, scal, **(extras or {}))
    tgt = target.float() / 255.0
    current = base[:, 4:7].float() / 255.0
    changed = ((tgt - current).abs().amax(1, keepdim=True) > CHANGED).float()
    weight = 1.0 + CHANGED_WEIGHT * changed
    l_img = ((out - tgt).abs() * weight).mean() / weight.mean()
    l_grip = (pred_grips - grips).abs().mean()
    loss = l_img + GRIP_WEIGHT * l_grip
    return loss, {"l1": float(l_img.detach()), "grip_l1": float(l_grip.detach())}


@torch.no_grad()
def validate(
    model: CompositeWorldModel, arrs: dict[str, np.ndarray[Any, Any]], idx: np.ndarray[Any, Any]
) -> dict[str, float]:
    """Pooled PSNR of the composite and of the static prior (where valid, else the current frame) on ``idx``."""
    model.eval()
    se, se_prior, se_changed, n_changed, grip_err = 0.0, 0.0, 0.0, 0.0, 0.0
    for chunk in np.array_split(idx, max(1, len(idx) // 64)):
        base, target, scal, grips = _tensors(arrs, chunk)
        out, pg = model.train_forward(base, scal, **_extras(model, arrs, chunk))
        tgt = target.float() / 255.0
        x = base.float() / 255.0
        prior = torch.where(x[:, 3:4] > 0.5, x[:, 0:3], x[:, 4:7])
        se += float(((out - tgt) ** 2).sum())
        se_prior += float(((prior - tgt) ** 2).sum())
        changed = ((tgt - x[:, 4:7]).abs().amax(1, keepdim=True) > CHANGED).float()
        se_changed += float((((out - tgt) ** 2) * changed).sum())
        n_changed += float(changed.sum()) * 3
        grip_err += float((pg - grips).abs().sum())
    model.train()
    total = len(idx) * 3 * arrs["targets"].shape[-1] ** 2

    def psnr(s: float, n: float) -> float:
        return 10 * math.log10(1.0 / max(s / max(n, 1.0), 1e-12))

    return {
        "psnr": psnr(se, total),
        "psnr_prior": psnr(se_prior, total),
        "psnr_changed": psnr(se_changed, n_changed),
        "grip_mae": grip_err / (2 * len(idx)),
    }


def train_composite(
    settings: TrainSettings,
    out: str | Path,
    *,
    checkpoint_every: int = 250,
    validate_every: int = 500,
    val_samples: int = 1024,
    log_every: int = 50,
    threads: int | None = None,
    progress: bool = True,
    rig: Any = None,
    stop_after: int | None = None,
    cache_dir: str | Path | None = None,
    cache_only: bool = False,
) -> Path | None:
    """Train (or resume) world model v2 into ``out``; returns ``out/model``. ``rig``: a loaded RigConfig
    to use instead of loading ``settings.rig`` (tests use small images). ``stop_after``: checkpoint and
    return None after that many steps of the schedule (a run split across sessions; rerun to continue).
    ``cache_dir``: the sample cache's folder (default ``out/cache``); the variants of one recipe share one,
    since it depends only on the data, sizes and seed. ``cache_only``: build the cache (with the variants'
    extra inputs) and return None, training nothing."""
    from pilworld.config.rig import RigConfig
    from pilworld.world_model.composite.checkpoint import save_composite

    root = Path(out)
    root.mkdir(parents=True, exist_ok=True)
    if threads:
        torch.set_num_threads(threads)
    settings_path = root / "settings.json"
    want = asdict(settings)
    if settings_path.is_file():
        have = json.loads(settings_path.read_text())
        diff = [k for k in want if k not in settings.schedule_keys() and have.get(k, _LATER_DEFAULTS.get(k)) != want[k]]
        if diff:
            raise ValueError(
                f"{root}: was started with other settings ({', '.join(f'{k}={have.get(k)!r}' for k in diff)}); "
                "resume with the same ones or choose a new --out"
            )
    settings_path.write_text(json.dumps(want, indent=2))
    spec = CacheSpec(
        settings.data, settings.rig, settings.cache_size, settings.frames_per_clip, settings.max_clips, settings.seed
    )
    cache = build_cache(spec, cache_dir or root / "cache", rig=rig, progress=progress)
    if settings.switches.needs_extras or cache_only:
        build_extras(spec, cache, rig=rig, progress=progress)
    if cache_only:
        return None
    arrs = _load(cache, settings.switches.needs_extras)
    episodes = np.asarray(arrs["episodes"])
    held_out = episodes % 20 == 0
    keep = ~held_out
    if settings.success_only:
        keep &= _successful(settings.data, episodes)
        if not keep.any():
            raise ValueError(f"{settings.data}: no successful episode among the cached training clips (success_only)")
    train_pool = np.flatnonzero(keep)
    val_pool = np.flatnonzero(held_out)
    val_idx = val_pool[np.random.default_rng(settings.seed + 1).permutation(len(val_pool))[:val_samples]]
    val_idx.sort()

    torch.manual_seed(settings.seed)
    rig_cfg = rig if rig is not None else RigConfig.load(settings.rig)
    config = CompositeConfig(
        rig=settings.rig,
        width=settings.width,
        work_size=settings.work_size,
        image_size=rig_cfg.image_size.width,
        switches=settings.switches,
    )
    model = CompositeWorldModel(config, rig_cfg)
    if progress and (not settings.switches.shipped or settings.success_only):
        what = settings.switches.describe() + (", success-only clips" if settings.success_only else "")
        print(f"variant: {what}; {len(train_pool)} training samples", flush=True)
    plate_file = Path(cache) / "plate.npy"
    if not plate_file.is_file():
        from pilworld.world_model.composite.plate import estimate_plate

        np.save(plate_file, estimate_plate(settings.data, rig_cfg, seed=settings.seed, progress=progress))
    with torch.no_grad():
        model.plate.copy_(torch.from_numpy(np.load(plate_file)))
    params = dict(model.named_parameters())
    names = {id(p): k for k, p in params.items()}
    opt = torch.optim.AdamW(params.values(), lr=settings.lr, weight_decay=1e-4)
    ema = EMA(params, 0.995)
    ckpts = root / "checkpoints"
    start = 0
    resume = latest_checkpoint(ckpts, PHASE)
    if resume is not None:
        load_checkpoint(resume, model, opt, names, ema)
        start = resume.step
    log = (root / "log.jsonl").open("a")
    bar = tqdm(total=settings.steps, initial=start, desc="v2 training", unit="step", disable=not progress)
    t0 = time.monotonic()
    for step in range(start, settings.steps):
        lr = settings.lr * min(1.0, (step + 1) / 100) * 0.5 * (1 + math.cos(math.pi * step / settings.steps))
        for g in opt.param_groups:
            g["lr"] = lr
        idx = _batch_indices(train_pool, settings.seed, step, settings.batch)
        base, target, scal, grips = _tensors(arrs, idx)
        gen = torch.Generator().manual_seed(settings.seed * 1_000_003 + step)
        base = _context_noise(base, gen, settings.context_noise)
        loss, terms = loss_terms(model, base, target, scal, grips, _extras(model, arrs, idx))
        opt.zero_grad(set_to_none=True)
        loss.backward()  # type: ignore[no-untyped-call]
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step()
        ema.update(params, step)
        bar.update(1)
        bar.set_postfix(l1=f"{terms['l1']:.4f}", grip=f"{terms['grip_l1']:.3f}")
        done = step + 1
        if done % log_every == 0:
            log.write(
                json.dumps({"step": done, "lr": lr, **terms, "elapsed_s": round(time.monotonic() - t0, 1)}) + "\n"
            )
            log.flush()
        if done % validate_every == 0 or done == settings.steps:
            live = {k: v.detach().clone() for k, v in params.items()}
            with torch.no_grad():
                for k, p in params.items():
                    p.copy_(ema.shadow[k])
            val = validate(model, arrs, val_idx)
            with torch.no_grad():
                for k, p in params.items():
                    p.copy_(live[k])
            log.write(json.dumps({"step": done, "validation": val}) + "\n")
            log.flush()
            bar.write(f"step {done}: validation {json.dumps({k: round(v, 3) for k, v in val.items()})}")
        if done % checkpoint_every == 0 or done == settings.steps or done == stop_after:
            save_checkpoint(ckpts, PHASE, done, model, opt, names, ema, {"settings": want})
        if done == stop_after and done < settings.steps:
            bar.close()
            log.close()
            return None
    bar.close()
    log.close()
    with torch.no_grad():
        for k, p in params.items():
            p.copy_(ema.shadow[k])
    return save_composite(model, root / "model")


def _successful(data: str, episodes: np.ndarray[Any, Any]) -> np.ndarray[Any, Any]:
    """Per sample: its episode succeeded (by the dataset's recorded outcomes; unknown counts as not)."""
    from pilworld.data.clip_dataset import episode_success

    ok = episode_success(Path(data), int(episodes.max()) + 1, None)
    return np.asarray(ok[episodes] == 1)
