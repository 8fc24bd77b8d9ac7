"""World-model variants run in closed loop on the same pairs (bench paired, speed-accuracy, stability).

A :class:`ModelVariant` is a world model plus how the imagined branch runs it (adapter, sampling steps,
history hidden or not, resized to the rig or not). :func:`evaluate_variants` runs one protocol — tasks ×
checkpoints × subtasks, R rounds, layout seeds — for several variants: the first variant's run executes
the real branches, and every other run copies them (``PairedConfig.real_from``), so the real side is
identical across variants and paid for once. Each run folder is then judged by the paper tasks'
hand-written image judge (success + automatic hallucination detector; the named reference) and, when the
protocol names one, by a learned judge whose verdicts SR and HFR then come from (the run's judge
selection); then it gets its ``metrics.json``. Everything resumes: rerun
the same call and finished branches, verdicts and metrics are reused.

The benchmark weights (the Ctrl-World-style baseline and the ablations, trained on the same data and
VAE as the shipped model; docs/RESULTS.md) live in ``weights/bench`` at the repository root, outside
the installed package.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pilworld.collection.workers import process_map, worker_count
from pilworld.types import ChunkSpec
from pilworld.world_model import V1_CHECKPOINT

if TYPE_CHECKING:
    from pilworld.config.rig import RigConfig

REPO_ROOT = Path(__file__).resolve().parents[2]
BENCH_WEIGHTS = REPO_ROOT / "weights" / "bench"
RESULT_FILE = "variant_result.json"


@dataclass(frozen=True)
class ModelVariant:
    """One world model as the imagined branch runs it."""

    name: str  # folder-safe key: "pilworld", "ctrl_world", ...
    label: str  # what the tables show
    world_model: str = ""  # model folder; "" = the packaged checkpoint
    adapter: str = "auto"  # "auto" | "none" | an adapter name
    steps: int | None = None  # sampling steps; None = the model's default
    history: bool = True  # False = the history memory hidden at inference
    resize: bool = False  # run a model of another image size resized to the rig's
    role: str = "model"  # "shipped" | "baseline" | "ablation" | "reference" | "model"
    note: str = ""
    trained_by: str = ""  # the command that makes the weights (named when they are missing)

    def __post_init__(self) -> None:
        if not self.name or any(c in self.name for c in "/\\ ") or self.name.startswith("."):
            raise ValueError(f"variant name: expected a folder-safe key, got {self.name!r}")
        if self.steps is not None and self.steps < 1:
            raise ValueError(f"variant {self.name}: steps must be >= 1, got {self.steps}")

    def check(self) -> None:
        """Raise ``FileNotFoundError`` naming the variant when its model folder is missing."""
        if self.world_model and not (Path(self.world_model) / "config.json").is_file():
            raise FileNotFoundError(
                f"variant {self.name!r}: no world model at {self.world_model} (config.json missing); "
                + (f"make it with {self.trained_by}" if self.trained_by else "see docs/RESULTS.md for the command")
            )


def bench_model(name: str) -> str:
    return str(BENCH_WEIGHTS / name)


def standard_variants() -> list[ModelVariant]:
    """The paper-style table's rows: ours, the Ctrl-World-style baseline, and the ablations.

    The Ctrl-World-style baseline had 3,500 Ψ_θ steps; ``pilworld_3500`` is our recipe at the same budget
    (v1's first stage), so the two compare at equal training. The ablations change one thing of v1 (the
    paper-style latent model, shipped until 2026-12-01): its history memory hidden at inference, or its
    stage-2 task adapters fine-tuned on successes only (the paper's stage 2 uses successes and failures).
    The shipped model is v2 (``pilworld``); its equal-budget ablations are docs/RESULTS.md §1's.
    """
    return [
        ModelVariant(
            "pilworld",
            "PiL-World v2 (shipped: Γ⁺ composite, tracked objects, predicted state)",
            adapter="none",
            role="shipped",
            note="docs/world_model.md, 'World model v2'",
        ),
        ModelVariant(
            "pilworld_v1",
            "PiL-World v1 (latent model, 9k steps, task adapters)",
            str(V1_CHECKPOINT),
            role="reference",
            note="the shipped model until v2 (its rows in results before 2026-12-02 are named 'pilworld')",
        ),
        ModelVariant(
            "ctrl_world",
            "Ctrl-World-style (action tokens, no control video, 3.5k)",
            bench_model("ctrl_world_3500"),
            adapter="none",
            role="baseline",
        ),
        ModelVariant(
            "pilworld_3500",
            "PiL-World at 3.5k steps (equal budget)",
            bench_model("pilworld_3500"),
            adapter="none",
            role="reference",
        ),
        ModelVariant(
            "no_history",
            "− history (v1, memory hidden)",
            str(V1_CHECKPOINT),
            history=False,
            role="ablation",
            note="inference-time: v1's weights with the latent history memory masked",
        ),
        ModelVariant(
            "success_only",
            "− failure data (v1's task adapters fine-tuned on successes only)",
            bench_model("success_only"),
            role="ablation",
            note="v1's stage-1 weights; stage 2 (150 LoRA steps per task) on successful clips only",
        ),
    ]


# docs/RESULTS.md §1: v2's recipe at equal budget (same data, cache, steps, network), one switch each
# (pilworld/world_model/composite/switches.py; scripts/train-bench-variants makes the weights).
V2_VARIANTS: tuple[tuple[str, str, str], ...] = (
    ("v2_paper_gamma", "paper-faithful: the paper's marker Γ (head view), no memory, no hand region", "baseline"),
    ("v2_ctrl_world", "Ctrl-World-style: per-frame action tokens, no control video", "baseline"),
    ("v2_markers", "Γ⁺ ablation: markers instead of the render (v2's memory and hand region kept)", "ablation"),
    ("v2_render", "Γ⁺ ablation: robot render only (no reprojection prior, robot not pasted)", "ablation"),
    ("v2_render_prior", "Γ⁺ ablation: render + reprojection prior (robot not pasted)", "ablation"),
    ("v2_no_history", "− history: the memory layer hidden in training and inference", "ablation"),
    ("v2_success_only", "− failure data: trained on clips of successful episodes only", "ablation"),
    ("v2_tokens", "+ action tokens: v2 with the frame's commanded action as extra inputs", "ablation"),
)


def v2_variants() -> list[ModelVariant]:
    """The equal-budget rows (docs/RESULTS.md §1): v2's recipe, one switch each, weights in ``weights/bench/<name>``."""
    return [
        ModelVariant(
            name,
            label,
            bench_model(name),
            adapter="none",
            role=role,
            note=f"trained by v2's recipe with one switch (weights/bench/{name}/COMMAND.txt)",
            trained_by=f"scripts/train-bench-variants {name}",
        )
        for name, label, role in V2_VARIANTS
    ]


@dataclass(frozen=True)
class PairedProtocol:
    """The pairs every variant runs: tasks × checkpoints × subtasks, R rounds, layouts from ``seed``."""

    tasks: tuple[str, ...]
    checkpoints: tuple[str, ...]
    subtasks: int
    rounds: int = 5
    seed: int = 6_000_000  # reserved for benchmark pairs (docs/RESULTS.md "Seeds")
    extra: dict[str, Any] = field(default_factory=dict)
    # A learned judge folder SR and HFR come from (its verdicts as judge "learned"); "" = the paper tasks'
    # hand-written image judge ("vision"), which judges every run either way as the named reference.
    judge: str = ""

    def __post_init__(self) -> None:
        if self.subtasks < 1 or self.rounds < 1:
            raise ValueError(f"protocol: subtasks and rounds must be >= 1, got {self.subtasks}, {self.rounds}")
        if not self.tasks or not self.checkpoints:
            raise ValueError("protocol: needs at least one task and one checkpoint")

    @property
    def pairs(self) -> int:
        return len(self.tasks) * len(self.checkpoints) * self.subtasks


def run_variant(
    variant: ModelVariant,
    protocol: PairedProtocol,
    out: Path,
    *,
    rig: str | Path,
    real_from: Path | None,
    workers: int | None,
    progress: bool,
    single_step: bool = True,
) -> dict[str, Any]:
    """Paired run + judging + metrics of one variant in ``out``; returns its result (also in ``RESULT_FILE``)."""
    from pilworld.config.rig import RigConfig
    from pilworld.data.judge_selection import write_selection
    from pilworld.judges.base import judge_dataset, unjudged_episodes
    from pilworld.judges.vision import VisionJudge
    from pilworld.metrics import write_metrics
    from pilworld.paired import PairedConfig, paired_run

    variant.check()
    t0 = time.monotonic()
    cfg = PairedConfig(
        rig=str(rig),
        task=",".join(protocol.tasks),
        checkpoints=list(protocol.checkpoints),
        subtasks=protocol.subtasks,
        out=str(out),
        seed=protocol.seed,
        world_model=variant.world_model,
        adapter=variant.adapter,
        steps=variant.steps,
        spec=ChunkSpec(rounds=protocol.rounds),
        real_from=str(real_from) if real_from is not None else "",
        history=variant.history,
        resize=variant.resize,
    )
    run = paired_run(cfg, progress=progress)
    paired_s = time.monotonic() - t0
    t = time.monotonic()
    reference = VisionJudge()
    todo = unjudged_episodes(out, reference.judge_id)
    rig_cfg = RigConfig.load(rig)
    if todo:
        judge_dataset(out, [reference], rig_cfg, episodes=todo, progress=progress, workers=workers)
    learned_new = _apply_learned(protocol.judge, out, rig_cfg, workers=workers, progress=progress)
    if not protocol.judge:
        write_selection(out, [reference.judge_id], "pilworld bench (the hand-written reference judge)")
    judging_s = time.monotonic() - t
    t = time.monotonic()
    cached = out / RESULT_FILE
    if run["branches_run"] == 0 and not todo and not learned_new and cached.is_file():
        # Nothing new was run or judged, so the stored metrics are this run's: reuse them (the single-step
        # SSIM of 300 pairs alone takes minutes). Delete the file to force a recomputation.
        metrics = json.loads(cached.read_text())["metrics"]
    else:
        metrics = write_metrics(out, out / "metrics.json", single_step=single_step, lpips=False)
    result = {
        "variant": asdict(variant),
        "out": str(out),
        "metrics": metrics,
        "imagined_seconds_per_subtask": run["seconds_per_subtask"].get("imagined"),
        "stages_s": {
            "paired": round(paired_s, 1),
            "judging": round(judging_s, 1),
            "metrics": round(time.monotonic() - t, 1),
        },
    }
    (out / RESULT_FILE).write_text(json.dumps(result))
    return result


def _apply_learned(judge: str, out: Path, rig: RigConfig, *, workers: int | None, progress: bool) -> bool:
    """Apply the learned judge folder ``judge`` to the run ``out`` and select it; whether any verdict changed."""
    if not judge:
        return False
    from pilworld.judges.learned.apply import apply_judge, read_record
    from pilworld.judges.learned.judge import LearnedSuccessJudge

    before = read_record(out)
    apply_judge(LearnedSuccessJudge(judge), out, rig, workers=workers, progress=progress, select_as="pilworld bench")
    return read_record(out) != before


def evaluate_variants(
    variants: Sequence[ModelVariant],
    protocol: PairedProtocol,
    out: str | Path,
    *,
    rig: str | Path,
    workers: int | None = None,
    progress: bool = True,
    single_step: bool = True,
    real_from: str | Path | None = None,
) -> dict[str, dict[str, Any]]:
    """Every variant on the protocol's pairs, the real branches run once (by the first variant).

    ``workers``: judging processes of the first variant, then processes running the other variants side
    by side (default: one per CPU). ``real_from``: a run folder of the same protocol whose real branches
    every variant copies, the first one included (e.g. a run made while a model was still training).
    """
    if not variants:
        raise ValueError("variants: expected at least one")
    names = [v.name for v in variants]
    if len(set(names)) != len(names):
        raise ValueError(f"variants: names listed twice: {names}")
    for v in variants:  # fail before hours of work, naming the missing model
        v.check()
    root = Path(out)
    root.mkdir(parents=True, exist_ok=True)
    first, rest = variants[0], list(variants[1:])
    if progress:
        print(f"[{first.name}] {first.label}: {protocol.pairs} pairs (its real branches are shared)", flush=True)
    reference = Path(real_from) if real_from is not None else root / first.name
    results = {
        first.name: run_variant(
            first,
            protocol,
            root / first.name,
            rig=rig,
            real_from=None if real_from is None or reference == root / first.name else reference,
            workers=workers,
            progress=progress,
            single_step=single_step,
        )
    }
    # The other variants only imagine (their real branches are copied), so they are independent: one process
    # each, ``workers`` at a time, one torch thread per process (2 cores: about twice as fast as one by one).
    lanes = worker_count(workers, len(rest))
    if progress and rest:
        print(f"{len(rest)} more variant(s) in {lanes} process(es): {', '.join(v.name for v in rest)}", flush=True)
    jobs = [
        (v, protocol, str(root / v.name), str(rig), str(reference), single_step, progress and lanes == 1) for v in rest
    ]
    for name, result in process_map(_variant_job, jobs, lanes, ordered=False):
        results[name] = result
        if progress:
            o = result["metrics"]["overall"]
            print(f"[{name}] done: |ΔSR| {o.get('abs_delta_sr')}, HFR {o.get('hfr')}", flush=True)
    return {v.name: results[v.name] for v in variants}


def _variant_job(
    job: tuple[ModelVariant, PairedProtocol, str, str, str, bool, bool],
) -> tuple[str, dict[str, Any]]:
    """One non-reference variant in a worker process (module level, so a spawned pool can pickle it)."""
    import torch

    variant, protocol, folder, rig, reference, single_step, progress = job
    torch.set_num_threads(1)
    result = run_variant(
        variant,
        protocol,
        Path(folder),
        rig=rig,
        real_from=Path(reference),
        workers=1,
        progress=progress,
        single_step=single_step,
    )
    return variant.name, result
