"""Labels → the run's outcomes table as judges ``human_1 … human_N`` (kind ``human``), then metrics and report.

Judge ``k`` of the annotation database becomes ``human_k``. Its rows in ``meta/outcomes.parquet`` are
replaced as a whole: rows for episodes it no longer has a label for (a database started afresh) go,
so the table always mirrors the database. The category is not part of the outcomes table (it is kept
in the database). ``write_metrics`` then recomputes ``metrics.json`` — SR, |ΔSR| and HFR average the
human judges with the others per pair, and ``human_agreement`` has the human-only figures and the
agreement statistics — and ``build_report`` rewrites ``report.html``.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pilworld.annotate.catalog import open_dataset
from pilworld.annotate.store import DB_FILE, AnnotationStore, StoredLabel, StoreError
from pilworld.data import layout
from pilworld.data.outcomes import Outcome, replace_judge_outcomes
from pilworld.data.pairs import is_paired


@dataclass
class ExportResult:
    outcomes_file: Path
    labels: dict[str, int] = field(default_factory=dict)  # human_k → rows written
    removed: int = 0  # stale human_k rows dropped
    metrics: Path | None = None
    report: Path | None = None
    skipped: str = ""  # why metrics and report were not recomputed


def judge_id(judge: int) -> str:
    return f"human_{judge}"


def open_existing(run_dir: str | Path) -> AnnotationStore:
    """The run's annotation database; ``StoreError`` when no judging session was ever started there."""
    if not (Path(run_dir) / DB_FILE).is_file():
        raise StoreError(f"RUN_DIR: {run_dir} has no {DB_FILE}; start a session with `pilworld annotate serve`")
    return AnnotationStore(run_dir)


def to_outcomes(labels: Iterable[StoredLabel], num_frames: dict[int, int]) -> list[Outcome]:
    return [
        Outcome(
            episode_index=s.episode_index,
            judge_id=judge_id(s.judge),
            judge_kind="human",
            success=s.label.success,
            num_frames=num_frames[s.episode_index],
            first_hallucination_frame=s.label.first_hallucination_frame,
            judged_at=s.updated_at,
        )
        for s in labels
    ]


def replace_judges(root: Path, judges: set[str], outcomes: list[Outcome]) -> int:
    """Drop every row of ``judges`` and add ``outcomes``, atomically; returns the rows dropped."""
    return replace_judge_outcomes(root, judges, outcomes)


def export_labels(
    run_dir: str | Path, *, metrics: bool = True, report: bool = True, metrics_kwargs: dict[str, Any] | None = None
) -> ExportResult:
    """Write every judge's labels as outcomes; then recompute metrics.json and report.html (unless told not to)."""
    root = Path(run_dir)
    dataset = open_dataset(root)
    store = open_existing(root)
    num_frames = {i: int(r["length"]) for i, r in enumerate(dataset.episodes)}
    labels = store.all_labels()
    unknown = sorted({s.episode_index for s in labels if s.episode_index not in num_frames})
    if unknown:
        raise StoreError(f"{store.path}: labels for episodes {unknown} that {root} does not have (another run?)")
    outcomes = to_outcomes(labels, num_frames)
    judges = {judge_id(j) for j in store.judges()}
    result = ExportResult(outcomes_file=root / layout.OUTCOMES)
    result.removed = replace_judges(root, judges, outcomes)
    result.labels = {j: sum(1 for o in outcomes if o.judge_id == j) for j in sorted(judges)}
    if (metrics or report) and not is_paired(dataset):
        result.skipped = "not a paired run (no episode has extra.pair): metrics and report need pairs"
        return result
    if metrics:
        from pilworld.metrics.report import METRICS_FILE, write_metrics

        write_metrics(root, **(metrics_kwargs or {}))
        result.metrics = root / METRICS_FILE
    if report:
        from pilworld.report import build_report

        result.report = build_report(root)
    return result
