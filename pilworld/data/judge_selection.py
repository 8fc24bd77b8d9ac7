"""Which judges' verdicts a run's SR and HFR come from: the run's judge selection (docs/metrics.md, "Which judges").

A run folder may hold verdicts of several judges on the same episodes — a learned judge, the paper tasks'
hand-written reference, operators, people in the annotation app. By default (no selection) SR and HFR
average every judge that gave a verdict on both branches of a pair, the paper's formula. A selection
names the judges that count instead; it lives in the run folder (``RUN_DIR/judges/selection.json``) so
every later recomputation — ``pilworld report``, ``annotate export``, another ``judge apply`` — scores the
run the same way, and ``metrics.json`` states it (``judges.selection``). The other judges' own rates stay
in ``judges.per_judge``, beside the selected ones, on the same pairs.

``pilworld judge apply`` selects the learned judge it applied (``--no-select``: not); ``pilworld judge
select RUN_DIR IDS|all`` sets it by hand.
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pilworld.io.atomic import write_json

SELECTION_FILE = Path("judges") / "selection.json"
FORMAT = "pilworld-judge-selection/1"
_ID = re.compile(r"^[A-Za-z0-9_.:-]{1,64}$")


class JudgeSelectionError(ValueError):
    """A selection file that cannot be read, or judge ids that cannot be selected."""


@dataclass(frozen=True)
class JudgeSelection:
    """``judges``: the judge ids whose verdicts count in SR and HFR; None = every both-branch judge (the default)."""

    judges: tuple[str, ...] | None
    set_by: str = "default"

    def allows(self, judge_id: str) -> bool:
        return self.judges is None or judge_id in self.judges

    def as_json(self) -> dict[str, Any]:
        return {
            "judges": None if self.judges is None else list(self.judges),
            "rule": (
                "every judge with verdicts on both branches of a pair (the paper's formula)"
                if self.judges is None
                else "only these judges' verdicts count in SR and HFR; every judge's own rates are in per_judge"
            ),
            "set_by": self.set_by,
        }


DEFAULT = JudgeSelection(None)


def _valid_ids(judges: object) -> bool:
    """A non-empty list or tuple of judge ids (the one rule for the command line, the file and callers)."""
    return (
        isinstance(judges, list | tuple) and bool(judges) and all(isinstance(j, str) and _ID.match(j) for j in judges)
    )


def parse_judge_ids(text: str) -> tuple[str, ...] | None:
    """``"learned,human_1"`` → the ids; ``"all"`` → None (every judge). One line naming what is wrong otherwise."""
    text = text.strip()
    if text == "all":
        return None
    ids = tuple(dict.fromkeys(p.strip() for p in text.split(",")))
    if not _valid_ids(ids):
        raise JudgeSelectionError(
            f"judges: expected comma-separated judge ids (e.g. learned,human_1) or 'all', got {text!r}"
        )
    return ids


def read_selection(root: str | Path) -> JudgeSelection:
    """The run's selection; the default when the run has none. A damaged file raises, naming it."""
    path = Path(root) / SELECTION_FILE
    if not path.is_file():
        return DEFAULT
    try:
        data = json.loads(path.read_text())
        if data.get("format") != FORMAT:
            raise ValueError(f"format {data.get('format')!r}, expected {FORMAT!r}")
        judges = data["judges"]
        if judges is not None:
            if not isinstance(judges, list) or not _valid_ids(judges):
                raise ValueError(f"'judges' must be null or a non-empty list of judge ids, got {judges!r}")
            judges = tuple(judges)
        return JudgeSelection(judges, str(data.get("set_by", "unknown")))
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as e:
        raise JudgeSelectionError(
            f"{path}: not a judge selection ({e}); remove it, or set one with pilworld judge select"
        ) from e


def write_selection(root: str | Path, judges: Sequence[str] | None, set_by: str) -> JudgeSelection:
    """Record that ``judges`` (None: every judge) count in the run at ``root``; returns the selection."""
    selection = JudgeSelection(None if judges is None else tuple(judges), set_by)
    if selection.judges is not None and not _valid_ids(selection.judges):
        raise JudgeSelectionError(f"judges: expected a non-empty list of judge ids, got {list(selection.judges)!r}")
    write_json(Path(root) / SELECTION_FILE, {"format": FORMAT, **selection.as_json()})
    return selection
