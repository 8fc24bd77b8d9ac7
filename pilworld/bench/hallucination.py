"""``pilworld bench hallucination``: the hallucination detector on real-branch episodes with injected faults.

For every clean real-branch episode of a dataset (or a seeded sample) the detector judges the episode
itself — any flag is a false positive — and one faulted copy per fault type of
:mod:`pilworld.judges.faults`, each at a frame ``k`` drawn from the middle half of the episode (seeded;
if the fault cannot be applied there, up to ``attempts`` other frames are tried, then the case is
counted as skipped). A faulted copy counts as

* ``detected`` when the first hallucination frame is within ``k ± 1``;
* ``early`` when it is before ``k - 1`` (the clean part was flagged), ``late`` after ``k + 1``;
* ``missed`` when nothing was found.

Reported per fault type and overall: counts, the detection rate, the categories the detector named,
the false-positive rate on the clean episodes with their categories, seconds per judged episode, and
the first cases that were not detected (to look at).

Each rate comes with a 95 % Wilson interval: on one set of 75 episodes a detection rate near 90 % is known to about
±7 points, and which frames and objects the seed draws moves it as much (one set's deletions measured 85.1 % and
95.9 % with two draws, docs/judges.md). ``draws`` injects each fault that many times per clean episode, at frames
drawn independently; the copies of one episode are not independent, so the interval is then somewhat too narrow.
"""

from __future__ import annotations

import argparse
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from pilworld.bench.flags import add_json, add_rig
from pilworld.bench.output import emit
from pilworld.config.rig import RigConfig
from pilworld.data.episode import Episode
from pilworld.data.reader import EpisodeStore
from pilworld.judges.base import JudgeContext, episode_task
from pilworld.judges.faults import FAULTS, FaultError, inject
from pilworld.judges.hallucination import HallucinationDetector
from pilworld.judges.hallucination_checks import Thresholds

# The acceptance of docs/judges.md, "Injected faults and the benchmark":
DETECTION_TARGET = 0.90  # frame k ± 1 found in at least 90 % of faulted episodes
FALSE_POSITIVE_LIMIT = 0.05  # ... and at most 5 % of clean real episodes flagged


def _category(reason: str) -> str:
    return reason.split(":", 1)[0]


def _outcome(frame: int | None, k: int) -> str:
    """A faulted copy's outcome: its first hallucination ``frame`` against the fault's frame ``k``."""
    if frame is None:
        return "missed"
    if abs(frame - k) <= 1:
        return "detected"
    return "early" if frame < k else "late"


def wilson(successes: int, n: int, z: float = 1.96) -> list[float] | None:
    """The 95 % Wilson score interval of a rate ``successes / n`` (None when ``n`` is 0)."""
    if n <= 0:
        return None
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return [round(float(max(0.0, centre - half)), 4), round(float(min(1.0, centre + half)), 4)]


def draw_k(length: int, rng: np.random.Generator) -> int:
    """A fault frame in the middle half of an episode of ``length`` frames."""
    lo, hi = max(1, length // 4), max(2, (3 * length) // 4)
    return int(rng.integers(lo, hi + 1)) if hi < length else int(rng.integers(lo, length))


def inject_random(
    fault: str, ep: Episode, rig: RigConfig, rng: np.random.Generator, *, attempts: int = 8
) -> tuple[Episode, int] | None:
    """``fault`` injected at a frame drawn by :func:`draw_k` (up to ``attempts`` frames tried), or None."""
    for _ in range(attempts):
        k = draw_k(ep.length, rng)
        try:
            return inject(fault, ep, k, rig, rng), k
        except FaultError:
            continue
    return None


def run_hallucination_bench(
    dataset_root: str | Path,
    rig: RigConfig | str | Path,
    *,
    seed: int = 0,
    per_fault: int | None = None,
    draws: int = 1,
    faults: tuple[str, ...] = FAULTS,
    attempts: int = 8,
    thresholds: Thresholds | None = None,
    progress: bool = False,
) -> dict[str, Any]:
    """Detection within ``k ± 1`` per fault type and false positives on clean episodes (see the module doc).

    ``per_fault``: how many clean episodes to use (each judged clean and once per fault); None = every
    real-branch episode of ``dataset_root``. Episodes are drawn in a seeded random order. ``draws``: faulted
    copies per fault type and clean episode (1 reproduces every earlier figure of a seed).
    """
    from pilworld.bench.common import machine_info

    unknown = [f for f in faults if f not in FAULTS]
    if unknown or not faults:
        raise ValueError(f"faults: expected a non-empty subset of {list(FAULTS)}, got {list(faults)}")
    if per_fault is not None and (isinstance(per_fault, bool) or not isinstance(per_fault, int) or per_fault < 1):
        raise ValueError(f"per_fault: expected None or an integer >= 1, got {per_fault!r}")
    if isinstance(draws, bool) or not isinstance(draws, int) or draws < 1:
        raise ValueError(f"draws: expected an integer >= 1, got {draws!r}")
    rig_cfg = rig if isinstance(rig, RigConfig) else RigConfig.load(rig)
    store = EpisodeStore(dataset_root)
    real = [i for i, row in enumerate(store.episodes) if _origin(store, i, row) == "real"]
    if not real:
        raise ValueError(f"dataset_root: {dataset_root} has no real-branch episodes")
    rng = np.random.default_rng(seed)
    order = [real[i] for i in rng.permutation(len(real))]
    chosen = order if per_fault is None else order[:per_fault]
    detector = HallucinationDetector(thresholds or Thresholds())

    clean_flags: Counter[str] = Counter()
    clean_cases: list[dict[str, Any]] = []
    per: dict[str, dict[str, Any]] = {
        f: {"n": 0, "detected": 0, "early": 0, "late": 0, "missed": 0, "skipped": 0, "categories": Counter()}
        for f in faults
    }
    misses: list[dict[str, Any]] = []
    judge_seconds: list[float] = []
    iterator: Any = chosen
    if progress:
        from tqdm import tqdm

        iterator = tqdm(chosen, desc="hallucination bench", unit="episode")
    for index in iterator:
        ep = store.load(index)
        ctx = JudgeContext(rig=rig_cfg, task=episode_task(ep))
        t0 = time.perf_counter()
        verdict = detector.judge(ep, ctx)
        judge_seconds.append(time.perf_counter() - t0)
        if verdict.first_hallucination_frame is not None:
            clean_flags[_category(verdict.reason)] += 1
            clean_cases.append({"episode": index, "frame": verdict.first_hallucination_frame, "reason": verdict.reason})
        for fault in faults:
            stats = per[fault]
            for _ in range(draws):
                case = inject_random(fault, ep, rig_cfg, rng, attempts=attempts)
                if case is None:
                    stats["skipped"] += 1
                    continue
                faulted, k = case
                t0 = time.perf_counter()
                v = detector.judge(faulted, ctx)
                judge_seconds.append(time.perf_counter() - t0)
                stats["n"] += 1
                f = v.first_hallucination_frame
                outcome = _outcome(f, k)
                stats[outcome] += 1
                if outcome == "detected":
                    stats["categories"][_category(v.reason)] += 1
                else:
                    misses.append(
                        {
                            "episode": index,
                            "fault": faulted.extra["fault"],
                            "frame": f,
                            "outcome": outcome,
                            "reason": v.reason,
                        }
                    )

    faults_out: dict[str, Any] = {}
    total_n = total_detected = 0
    for fault, stats in per.items():
        n = int(stats["n"])
        total_n += n
        total_detected += int(stats["detected"])
        faults_out[fault] = {
            **{key: int(stats[key]) for key in ("n", "detected", "early", "late", "missed", "skipped")},
            "detection_rate": stats["detected"] / n if n else None,
            "detection_ci95": wilson(int(stats["detected"]), n),
            "categories": dict(stats["categories"]),
        }
    n_clean = len(chosen)
    fp_rate = len(clean_cases) / n_clean
    detection = total_detected / total_n if total_n else 0.0
    worst = min((v["detection_rate"] for v in faults_out.values() if v["detection_rate"] is not None), default=0.0)
    return {
        "dataset": str(dataset_root),
        "seed": seed,
        "draws": draws,
        "episodes": n_clean,
        "clean": {
            "n": n_clean,
            "flagged": len(clean_cases),
            "false_positive_rate": fp_rate,
            "false_positive_ci95": wilson(len(clean_cases), n_clean),
            "categories": dict(clean_flags),
            "cases": clean_cases,
        },
        "faults": faults_out,
        "overall": {
            "n": total_n,
            "detected": total_detected,
            "detection_rate": detection,
            "detection_ci95": wilson(total_detected, total_n),
        },
        "acceptance": {
            "detection_target": DETECTION_TARGET,
            "false_positive_limit": FALSE_POSITIVE_LIMIT,
            "overall_detection_ok": detection >= DETECTION_TARGET,
            "every_fault_detection_ok": worst >= DETECTION_TARGET,
            "false_positive_ok": fp_rate <= FALSE_POSITIVE_LIMIT,
        },
        "seconds_per_episode": float(np.mean(judge_seconds)) if judge_seconds else None,
        "not_detected": misses,
        "machine": machine_info(),
    }


def _origin(store: EpisodeStore, index: int, row: dict[str, Any]) -> str:
    """An episode's branch; the per-frame column is the source of truth, the episodes table may lack it."""
    if row.get("origin"):
        return str(row["origin"])
    table = store.frame_table(index)
    if "origin" in table.column_names and table.num_rows:
        return str(table.column("origin")[0].as_py())
    return "real"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dataset", type=Path, help="a dataset of real-branch episodes (e.g. from pilworld sim collect)")
    add_rig(parser)
    parser.add_argument("--per-fault", type=int, default=None, help="faulted episodes per fault type (default: all)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--draws", type=int, default=1, help="faulted copies per fault type and clean episode, at independent frames"
    )
    add_json(parser)


def run(args: argparse.Namespace) -> int:
    """The result's scalar figures in one line (its lists and tables only with ``--json``)."""
    r = run_hallucination_bench(
        args.dataset, args.rig, seed=args.seed, per_fault=args.per_fault, draws=args.draws, progress=not args.json
    )
    summary = {k: v for k, v in r.items() if not isinstance(v, (list, dict))}
    return emit(args, r, [", ".join(f"{k} {v}" for k, v in summary.items())])
