"""The person at a real rig: sets up each subtask's scene and, at the end, says whether it succeeded.

:class:`ConsoleOperator` asks on the terminal; tests pass scripted answers through ``ask``. The verdict
is stored as a ``human`` judge (``judge_id`` "operator"); "skip" leaves the episode to the annotation
app (issue #10) and records nothing.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, runtime_checkable

from pilworld.types import Subtask

OPERATOR_JUDGE = "operator"
YES = ("y", "yes", "s", "success")
NO = ("n", "no", "f", "fail", "failure")
SKIP = ("", "skip", "?")


@runtime_checkable
class Operator(Protocol):
    def set_up(self, subtask: Subtask, checkpoint: str) -> None:
        """Return once the scene of ``subtask`` is set up (objects placed, nothing in the arms' way)."""
        ...

    def judge(self, subtask: Subtask, checkpoint: str) -> bool | None:
        """Success (True), failure (False), or None to leave it to the annotation app."""
        ...


class ConsoleOperator:
    """Prompts on the terminal (or through ``ask``/``tell`` in tests); re-asks until the answer is valid."""

    def __init__(
        self,
        ask: Callable[[str], str] = input,
        tell: Callable[[str], None] = print,
        *,
        judge_outcomes: bool = True,
        max_attempts: int = 5,
    ) -> None:
        self.ask = ask
        self.tell = tell
        self.judge_outcomes = judge_outcomes
        self.max_attempts = max_attempts

    def set_up(self, subtask: Subtask, checkpoint: str) -> None:
        self.tell(
            f"\n[{checkpoint}] {subtask.task} subtask {subtask.index} (layout seed {subtask.seed}): "
            f"set up the scene for “{subtask.instruction}” with the subtasks before it done."
        )
        self.ask("Press Enter when the scene is ready and the arms' path is clear (Ctrl-C to stop) ")

    def judge(self, subtask: Subtask, checkpoint: str) -> bool | None:
        if not self.judge_outcomes:
            return None
        for _ in range(self.max_attempts):
            answer = self.ask(f"Did {subtask.task} subtask {subtask.index} succeed? [y]es / [n]o / Enter: skip ")
            a = answer.strip().lower()
            if a in YES:
                return True
            if a in NO:
                return False
            if a in SKIP:
                return None
            self.tell(f"Please answer y, n, or press Enter to skip (got {answer!r}).")
        raise ValueError(f"operator: no valid answer after {self.max_attempts} attempts")
