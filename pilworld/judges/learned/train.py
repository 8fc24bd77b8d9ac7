"""Training the learned success judge: k folds, calibrated probabilities, an abstention threshold (docs/judges.md).

1. **Folds by layout.** Labelled episodes are split into ``folds`` groups by (dataset, layout seed), so
   the episodes of one scene (every checkpoint run on it) are never both trained on and validated on.
2. **One network per fold**, trained on the other folds with augmentations a camera and a world model
   cause: a few pixels of shift, colour gain and offset per view, sensor noise, blur on a share of the
   samples, and on another share the end frames alone softened and tinted as a world model renders them
   (an imagined rollout starts from a real frame). Its predictions on its own held-out fold
   are the *out-of-fold* predictions: every labelled episode judged by a network that never saw it.
3. **Calibration.** One temperature, fitted to the out-of-fold logits by likelihood, makes the reported
   probabilities honest (a verdict given at 0.9 is right about 9 times in 10).
4. **Abstention.** The judge answers when its calibrated confidence ``max(p, 1 − p)`` reaches a
   threshold: the lowest at which out-of-fold accuracy on the answered episodes reaches ``target``,
   abstaining on at most ``abstain_budget`` of them (else the threshold the budget allows). Abstentions
   go to people (the annotation app).

The judge then is the ensemble of the fold networks (mean logit over networks and over the last frames),
divided by the temperature. All of it seeded: the same data and settings give the same judge.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from numpy.typing import NDArray
from tqdm import tqdm

from pilworld.config.rig import RigConfig
from pilworld.judges.learned.examples import stack_examples, stored_example
from pilworld.judges.learned.inputs import InputSpec, instruction_key
from pilworld.judges.learned.labels import JudgeDataError, Labelled, open_store
from pilworld.judges.learned.net import ARCHS, JudgeNet


@dataclass(frozen=True)
class TrainSettings:
    folds: int = 5
    steps: int = 300  # optimiser steps per fold network
    batch: int = 32
    lr: float = 2e-3
    weight_decay: float = 1e-3
    side: int = 64
    width: int = 16
    arch: str = "grid"  # the view encoder: "grid" (a flattened 4 × 4 grid) or "keypoints" (spatial softmax)
    release_crop: int = 0  # > 0: also read a crop of this many head pixels where a gripper last let go
    imagined: float = 0.5  # share of samples whose end frames get a world model's look (blur, colour drift)
    abstain_budget: float = 0.04  # abstain on at most this share of the out-of-fold episodes …
    target: float = 0.99  # … and stop abstaining once the answered ones are this accurate
    seed: int = 0

    def __post_init__(self) -> None:
        checks = {
            "folds": 2 <= self.folds <= 20,
            "steps": 1 <= self.steps <= 100_000,
            "batch": 1 <= self.batch <= 4096,
            "lr": 0 < self.lr < 1,
            "weight_decay": 0 <= self.weight_decay < 1,
            "side": self.side in (32, 48, 64, 80, 96, 112, 128),
            "width": 4 <= self.width <= 256 and self.width % 4 == 0,
            "arch": self.arch in ARCHS,
            "release_crop": self.release_crop == 0 or 8 <= self.release_crop <= 256,
            "imagined": 0 <= self.imagined <= 1,
            "abstain_budget": 0 <= self.abstain_budget < 1,
            "target": 0.5 < self.target <= 1,
        }
        bad = [k for k, ok in checks.items() if not ok]
        if bad:
            raise ValueError(f"judge settings out of range: {', '.join(f'{k}={getattr(self, k)}' for k in bad)}")


@dataclass
class TrainedJudge:
    spec: InputSpec
    settings: TrainSettings
    nets: list[JudgeNet]
    temperature: float
    threshold: float
    instructions: dict[str, int]  # instruction key → labelled episodes
    validation: dict[str, Any]  # out-of-fold figures


@dataclass(frozen=True)
class Data:
    frames: NDArray[np.uint8]  # (N, E, V, 6, S, S)
    state: NDArray[np.float32]  # (N, E, 2D)
    context: NDArray[np.float32]  # (N, C)
    labels: NDArray[np.float32]  # (N,)
    groups: NDArray[np.int64]  # (N,) layout group
    instructions: list[str]


def dataset_spec(labelled: Sequence[Labelled], side: int, release_crop: int = 0) -> InputSpec:
    """The cameras and state of the training data; every dataset must record the same."""
    spec: InputSpec | None = None
    for root in dict.fromkeys(lab.root for lab in labelled):
        s = open_store(root).spec
        mine = InputSpec.from_views(s.views, s.state_dim, side, release_crop)
        if spec is None:
            spec = mine
        elif (mine.views, mine.image_sizes, mine.state_dim) != (spec.views, spec.image_sizes, spec.state_dim):
            raise JudgeDataError(
                f"--data: {root} records cameras {dict(zip(mine.views, mine.image_sizes, strict=True))} and a "
                f"{mine.state_dim}-value state, the first dataset "
                f"{dict(zip(spec.views, spec.image_sizes, strict=True))} and {spec.state_dim}: one judge per rig"
            )
    assert spec is not None
    return spec


def read_data(
    labelled: Sequence[Labelled], spec: InputSpec, progress: bool = True, rig: RigConfig | None = None
) -> Data:
    stores = {root: open_store(root) for root in dict.fromkeys(lab.root for lab in labelled)}
    examples = [
        stored_example(stores[lab.root], lab.index, spec, rig)
        for lab in tqdm(labelled, desc="reading episodes", unit="episode", disable=not progress)
    ]
    group_ids: dict[tuple[str, int], int] = {}
    groups = [group_ids.setdefault((str(lab.root), lab.seed), len(group_ids)) for lab in labelled]
    frames, state, context = stack_examples(examples)
    return Data(
        frames=frames,
        state=state,
        context=context,
        labels=np.array([lab.success for lab in labelled], dtype=np.float32),
        groups=np.array(groups, dtype=np.int64),
        instructions=[instruction_key(e.instruction) for e in examples],
    )


def fold_of(groups: NDArray[np.int64], folds: int, seed: int) -> NDArray[np.int64]:
    """Each layout group to a fold, shuffled with ``seed``; folds as equal in episodes as the groups allow."""
    rng = np.random.default_rng(seed)
    unique, counts = np.unique(groups, return_counts=True)
    order = rng.permutation(len(unique))
    load = np.zeros(folds, dtype=np.int64)
    assign: dict[int, int] = {}
    for i in order[np.argsort(-counts[order], kind="stable")]:  # biggest groups first, ties in shuffled order
        f = int(np.argmin(load))
        assign[int(unique[i])] = f
        load[f] += counts[i]
    return np.array([assign[int(g)] for g in groups], dtype=np.int64)


def _augment(frames: torch.Tensor, gen: torch.Generator) -> torch.Tensor:
    """(B, V, 6, S, S) in [0, 1]: shift, colour gain/offset and noise per view (same for its two frames), blur."""
    B, V, C, S, _ = frames.shape
    pad = 4
    padded = F.pad(frames.flatten(0, 1), (pad, pad, pad, pad), mode="replicate")
    shifts = torch.randint(0, 2 * pad + 1, (B * V, 2), generator=gen)
    out = torch.stack([padded[i, :, y : y + S, x : x + S] for i, (y, x) in enumerate(shifts.tolist())])
    out = out.view(B, V, 2, 3, S, S)
    gain = 1 + 0.15 * (2 * torch.rand(B, V, 1, 3, 1, 1, generator=gen) - 1)
    offset = 0.05 * (2 * torch.rand(B, V, 1, 1, 1, 1, generator=gen) - 1)
    noise = 0.03 * torch.rand(B, V, 1, 1, 1, 1, generator=gen) * torch.randn(out.shape, generator=gen)
    out = (out * gain + offset + noise).view(B * V, C, S, S)
    blur = torch.rand(B * V, generator=gen) < 0.3
    if bool(blur.any()):
        out[blur] = F.avg_pool2d(out[blur], 3, 1, 1, count_include_pad=False)
    return out.clamp(0, 1).view(B, V, C, S, S)


IMAGINED_SIGMA = (0.4, 1.6)  # Gaussian blur of an imagined end frame, in recorded pixels (uniform)
IMAGINED_DRIFT = 0.04  # colour drift of an imagined end frame, per channel (uniform ±)


def _gaussian(frames: torch.Tensor, sigma: float) -> torch.Tensor:
    """(N, C, S, S) blurred by a separable Gaussian of ``sigma`` pixels (borders repeated)."""
    r = max(1, math.ceil(3 * sigma))
    x = torch.arange(-r, r + 1, dtype=frames.dtype)
    k = torch.exp(-0.5 * (x / sigma) ** 2)
    k = k / k.sum()
    n, c, s, _ = frames.shape
    flat = F.pad(frames.reshape(n * c, 1, s, s), (r, r, r, r), mode="replicate")
    flat = F.conv2d(flat, k.view(1, 1, 1, -1))
    flat = F.conv2d(flat, k.view(1, 1, -1, 1))
    return flat.view(n, c, s, s)


def _imagined_look(frames: torch.Tensor, gen: torch.Generator, share: float, scales: Sequence[float]) -> torch.Tensor:
    """(B, V, 6, S, S): on ``share`` of the samples, the **end** frame of every input (channels 3–5) as a world
    model renders it — softer (a Gaussian of 0.4–1.6 recorded pixels) and with a slight colour drift — while
    the start frame stays sharp: an imagined rollout starts from a real frame. Trained without it, a judge
    reads a faithful but soft rendering as a changed scene (docs/judges.md, "Fairness").

    ``scales``: input pixels per recorded pixel, per input (a view resized from 128 to 64: 0.5; a 32-pixel
    release crop resized to 64: 2)."""
    B = frames.shape[0]
    chosen = torch.rand(B, generator=gen) < share
    sigmas = IMAGINED_SIGMA[0] + (IMAGINED_SIGMA[1] - IMAGINED_SIGMA[0]) * torch.rand(B, generator=gen)
    drift = IMAGINED_DRIFT * (2 * torch.rand(B, 1, 3, 1, 1, generator=gen) - 1)
    out = frames.clone()
    for b in torch.nonzero(chosen).flatten().tolist():
        for v, scale in enumerate(scales):
            sigma = float(sigmas[b]) * scale
            if sigma >= 0.2:  # below that the kernel is all centre
                out[b, v, 3:] = _gaussian(out[b, v, 3:].unsqueeze(0), sigma)[0]
        out[b, :, 3:] = out[b, :, 3:] + drift[b]
    return out.clamp(0, 1)


def input_scales(spec: InputSpec) -> list[float]:
    """Input pixels per recorded pixel for every input the network reads (the views, then the release crop)."""
    scales = [spec.side / max(h, w) for h, w in spec.image_sizes]
    if spec.release_crop:
        scales.append(spec.side / spec.release_crop)
    return scales


def _batch(data: Data, idx: NDArray[np.int64], ends: NDArray[np.int64]) -> tuple[torch.Tensor, ...]:
    frames = torch.from_numpy(data.frames[idx, ends]).float().div_(255)
    return frames, torch.from_numpy(data.state[idx, ends]), torch.from_numpy(data.context[idx])


def predict_logits(net: JudgeNet, data: Data, idx: NDArray[np.int64], batch: int = 64) -> NDArray[np.float32]:
    """Mean logit over the last frames (E variants) for episodes ``idx``; the net in eval mode."""
    net.eval()
    E = data.frames.shape[1]
    out = np.zeros(len(idx), dtype=np.float32)
    with torch.no_grad():
        for s in range(0, len(idx), batch):
            chunk = idx[s : s + batch]
            acc = torch.zeros(len(chunk))
            for e in range(E):
                acc += net(*_batch(data, chunk, np.full(len(chunk), e)))
            out[s : s + len(chunk)] = (acc / E).numpy()
    return out


def train_net(data: Data, idx: NDArray[np.int64], settings: TrainSettings, seed: int, spec: InputSpec) -> JudgeNet:
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    rng = np.random.default_rng(seed)
    net = JudgeNet(spec.inputs, spec.state_dim, spec.side, settings.width, arch=settings.arch)
    st = data.state[idx].reshape(-1, data.state.shape[-1])
    net.state_mean.copy_(torch.from_numpy(st.mean(0)))
    net.state_std.copy_(torch.from_numpy(st.std(0) + 1e-3))
    y = data.labels[idx]
    pos = float(y.mean())
    pos_weight = torch.tensor((1 - pos) / max(pos, 1e-6))  # a rare class counts as much as a common one
    opt = torch.optim.AdamW(net.parameters(), lr=settings.lr, weight_decay=settings.weight_decay)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, settings.lr, total_steps=settings.steps, pct_start=0.15)
    E = data.frames.shape[1]
    scales = input_scales(spec)
    net.train()
    for _ in range(settings.steps):
        pick = rng.choice(len(idx), size=min(settings.batch, len(idx)), replace=len(idx) < settings.batch)
        chosen = idx[pick]
        frames, state, context = _batch(data, chosen, rng.integers(0, E, len(chosen)))
        frames = _augment(frames, gen)
        if settings.imagined > 0:  # off, it draws nothing from ``gen``: the judges trained before it reproduce
            frames = _imagined_look(frames, gen, settings.imagined, scales)
        logits = net(frames, state, context)
        loss = F.binary_cross_entropy_with_logits(logits, torch.from_numpy(data.labels[chosen]), pos_weight=pos_weight)
        opt.zero_grad(set_to_none=True)
        loss.backward()  # type: ignore[no-untyped-call]
        opt.step()
        sched.step()
    net.eval()
    return net


def sigmoid(x: NDArray[np.float64] | np.float64) -> NDArray[np.float64]:
    """1 / (1 + e^(−x)) without overflow at large |x|."""
    return np.asarray(0.5 * (1 + np.tanh(0.5 * x)), np.float64)


def fit_temperature(logits: NDArray[np.float32], labels: NDArray[np.float32]) -> float:
    """The temperature T minimising the log loss of sigmoid(logits / T) (a grid, then its neighbourhood)."""

    def nll(t: float) -> float:
        z = logits / t
        return float(np.mean(np.logaddexp(0, z) - labels * z))

    grid = np.exp(np.linspace(math.log(0.05), math.log(20), 121))
    best = float(min(grid, key=nll))
    fine = np.linspace(best / 1.06, best * 1.06, 41)
    return float(min(fine, key=nll))


def choose_threshold(prob: NDArray[np.float64], labels: NDArray[np.float32], budget: float, target: float) -> float:
    """The confidence below which the judge abstains (see the module's docstring, step 4)."""
    conf = np.maximum(prob, 1 - prob)
    right = (prob >= 0.5) == (labels >= 0.5)
    n = len(conf)
    candidates = np.unique(np.concatenate([[0.5], conf]))
    allowed = 0.5
    for t in candidates:  # ascending: the first that reaches the target wins
        answered = conf >= t
        if (n - answered.sum()) / n > budget:
            break
        allowed = float(t)
        if answered.any() and right[answered].mean() >= target:
            return float(t)
    return allowed


def summarise(prob: NDArray[np.float64], labels: NDArray[np.float32], threshold: float) -> dict[str, Any]:
    conf = np.maximum(prob, 1 - prob)
    said = prob >= 0.5
    truth = labels >= 0.5
    answered = conf >= threshold
    bins = np.clip((conf * 10).astype(int), 5, 9)
    ece = sum(abs(((said == truth)[bins == b]).mean() - conf[bins == b].mean()) * (bins == b).mean()
              for b in range(5, 10) if (bins == b).any())  # fmt: skip
    return {
        "episodes": len(prob),
        "accuracy_all": round(float((said == truth).mean()), 4),
        "answered": int(answered.sum()),
        "abstained": int((~answered).sum()),
        "abstain_share": round(float((~answered).mean()), 4),
        "accuracy_answered": round(float((said == truth)[answered].mean()), 4) if answered.any() else None,
        "confusion_answered": {
            "true_pos": int((said & truth & answered).sum()),
            "false_pos": int((said & ~truth & answered).sum()),
            "true_neg": int((~said & ~truth & answered).sum()),
            "false_neg": int((~said & truth & answered).sum()),
        },
        "ece": round(float(ece), 4),
    }


def train_judge(
    labelled: Sequence[Labelled],
    settings: TrainSettings,
    *,
    progress: bool = True,
    log: Callable[[str], None] | None = None,
    rig: RigConfig | None = None,
) -> TrainedJudge:
    """Read the labelled episodes, train ``settings.folds`` networks, calibrate, choose the threshold.

    ``rig``: the rig the episodes were recorded on; needed for ``settings.release_crop``."""
    t0 = time.perf_counter()
    spec = dataset_spec(labelled, settings.side, settings.release_crop)
    data = read_data(labelled, spec, progress, rig)
    t_read = time.perf_counter() - t0
    folds = fold_of(data.groups, settings.folds, settings.seed)
    if len(np.unique(folds)) < settings.folds:
        raise JudgeDataError(
            f"--folds {settings.folds}: the labelled episodes come from only {len(np.unique(data.groups))} "
            "layouts; use fewer folds or label more episodes"
        )
    oof = np.zeros(len(labelled), dtype=np.float32)
    nets: list[JudgeNet] = []
    for k in tqdm(range(settings.folds), desc="training folds", unit="net", disable=not progress):
        train_idx = np.flatnonzero(folds != k)
        held = np.flatnonzero(folds == k)
        if len(np.unique(data.labels[train_idx])) < 2:
            raise JudgeDataError(f"fold {k}: its training part has one class only; label more episodes")
        net = train_net(data, train_idx, settings, settings.seed * 1000 + k, spec)
        oof[held] = predict_logits(net, data, held)
        nets.append(net)
    temperature = fit_temperature(oof, data.labels)
    prob = sigmoid(oof.astype(np.float64) / temperature)
    threshold = choose_threshold(prob, data.labels, settings.abstain_budget, settings.target)
    validation = summarise(prob, data.labels, threshold)
    validation["per_instruction"] = {
        key: summarise(prob[mask], data.labels[mask], threshold)
        for key in sorted(set(data.instructions))
        if (mask := np.array([i == key for i in data.instructions])).any()
    }
    validation["method"] = f"out-of-fold over {settings.folds} folds grouped by layout"
    validation["seconds"] = {"read": round(t_read, 1), "total": round(time.perf_counter() - t0, 1)}
    if log is not None:
        log(f"trained in {validation['seconds']['total']:.0f} s: {validation['accuracy_answered']} out-of-fold "
            f"accuracy, abstaining on {validation['abstain_share']:.1%}")  # fmt: skip
    counts: dict[str, int] = {}
    for key in data.instructions:
        counts[key] = counts.get(key, 0) + 1
    return TrainedJudge(spec, settings, nets, temperature, threshold, counts, validation)


def settings_json(settings: TrainSettings) -> dict[str, Any]:
    return asdict(settings)
