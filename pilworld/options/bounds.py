"""Bounds on the counts a user passes, each with its reason, shared by ``--help`` and the checks.

A count past its bound is refused before anything runs, in one line naming the flag, the bound and
why it is there: a typo (an extra zero, a pasted number) must not start a run that grows memory or a
database for hours. The bounds are far above any real use; ``--help`` states each.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass


@dataclass(frozen=True)
class Bound:
    lo: int
    hi: int
    why: str

    @property
    def text(self) -> str:
        return f"{self.lo}..{self.hi:,}; {self.why}"


SUBTASKS = Bound(1, 10_000, "each is a closed-loop episode per branch and checkpoint")
STARTS = Bound(1, 10_000, "each is a recorded scene")
EPISODES = Bound(1, 100_000, "runs per task and checkpoint")
WORKERS = Bound(1, 256, "processes on this machine")
JUDGES = Bound(1, 100, "each judge is a person with a token and a queue of every episode")
ROUNDS = Bound(1, 100, "closed-loop rounds per subtask")
SAMPLING_STEPS = Bound(1, 1_000, "sampling steps per chunk")
SEED = Bound(0, 2**32 - 1, "a layout seed")
SUBTASK_INDEX = Bound(0, 1_000_000, "a subtask of the layout")
SCALE = Bound(1, 16, "integer upscaling")
TRY_SUBTASKS = Bound(1, 1_000, "subtask starts per checkpoint")
SIM_REPEATS = Bound(1, 50, "speed measurements per appearance, each a closed-loop subtask")


def check_count(value: int | None, flag: str, bound: Bound) -> None:
    """Refuse ``value`` outside ``bound`` (None: not given, fine) in one line naming ``flag``."""
    if value is None:
        return
    if not bound.lo <= value <= bound.hi:
        shown = str(value) if len(str(value)) <= 24 else f"{str(value)[:12]}…({len(str(value))} digits)"
        raise ValueError(f"{flag}: expected an integer in {bound.lo}..{bound.hi:,} ({bound.why}), got {shown}")


def at_least_one(args: argparse.Namespace, *dests: str) -> None:
    """Refuse a count below 1 among ``args``' ``dests`` (None: not given, fine), in order, naming the flag."""
    for dest in dests:
        value = getattr(args, dest)
        if value is not None and value < 1:
            raise ValueError(f"--{dest.replace('_', '-')}: expected at least 1, got {value}")


def bounded(help_text: str, bound: Bound) -> str:
    """``help_text`` with the bound stated (what ``--help`` shows)."""
    return f"{help_text} [{bound.lo}..{bound.hi:,}]"
