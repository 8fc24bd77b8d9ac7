"""The person at a real rig: sets up each subtask's scene and, at the end, says whether it succeeded.

:class:`ConsoleOperator` asks on the terminal; tests pass scripted answers through ``ask``. The verdict
is stored as a ``human`` judge (``judge_id`` "operator"); "skip" leaves the episode to the annotation
app (docs/annotate.md) and records nothing.

Without a terminal (a script, CI, ``</dev/null``) nobody can answer: :meth:`ConsoleOperator.check_available`
raises :class:`OperatorUnavailableError` before the rig moves, and an answer that never comes (stdin
closed mid-run) raises it too instead of an ``EOFError``. :class:`UnattendedOperator` is the explicit
alternative on the fake rig only, where the simulator lays out each scene and its checker judges.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Protocol, runtime_checkable

from pilworld.types import Subtask

OPERATOR_JUDGE = "operator"
YES = ("y", "yes", "s", "success")
NO = ("n", "no", "f", "fail", "failure")
SKIP = ("", "skip", "?")


class OperatorUnavailableError(RuntimeError):
    """A hardware run needs a person at a terminal and there is none (stdin is not a terminal, or closed)."""


@runtime_checkable
class Operator(Protocol):
    def set_up(self, subtask: Subtask, checkpoint: str, *, setup: str = "") -> None:
        """Return once the scene of ``subtask`` is set up (objects placed, nothing in the arms' way);
        ``setup`` is the task file's ``operator_setup`` note for this subtask ("" when it has none)."""
        ...

    def judge(self, subtask: Subtask, checkpoint: str, *, success: str = "") -> bool | None:
        """Success (True), failure (False), or None to leave it to the annotation app; ``success`` is the
        task file's ``operator_success`` note (what counts as success) for this subtask."""
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

    def check_available(self, rig: str) -> None:
        """Raise :class:`OperatorUnavailableError` when prompts would go to no terminal (before any motion)."""
        if self.ask is input and not _stdin_is_a_terminal():
            raise OperatorUnavailableError(
                f"rig {rig}: a hardware run needs an operator at a terminal to set up each scene and judge it, "
                "and stdin is not a terminal; run it from a terminal (or, on the fake rig only, pass --unattended)"
            )

    def _ask(self, question: str) -> str:
        try:
            return self.ask(question)
        except EOFError:
            raise OperatorUnavailableError(
                "the operator's terminal closed (end of input) while the rig waited for an answer; "
                "branches stored so far stay, rerun the same command to resume"
            ) from None

    def set_up(self, subtask: Subtask, checkpoint: str, *, setup: str = "") -> None:
        self.tell(
            f"\n[{checkpoint}] {subtask.task} subtask {subtask.index} (layout seed {subtask.seed}): "
            f"set up the scene for “{subtask.instruction}” with the subtasks before it done."
        )
        if setup.strip():
            self.tell(f"Set-up: {setup.strip()}")
        self._ask("Press Enter when the scene is ready and the arms' path is clear (Ctrl-C to stop) ")

    def judge(self, subtask: Subtask, checkpoint: str, *, success: str = "") -> bool | None:
        if not self.judge_outcomes:
            return None
        if success.strip():
            self.tell(f"Success means: {success.strip()}")
        for _ in range(self.max_attempts):
            answer = self._ask(f"Did {subtask.task} subtask {subtask.index} succeed? [y]es / [n]o / Enter: skip ")
            a = answer.strip().lower()
            if a in YES:
                return True
            if a in NO:
                return False
            if a in SKIP:
                return None
            self.tell(f"Please answer y, n, or press Enter to skip (got {answer!r}).")
        raise ValueError(f"operator: no valid answer after {self.max_attempts} attempts")


class UnattendedOperator:
    """Nobody at the rig: the fake rig's simulator lays out each scene (``FakeRig.reset``) and its
    privileged checker judges; no ``operator`` verdict is recorded. Refused on real hardware
    (:class:`~pilworld.paired.stations.HardwareStation`), where nobody would clear the table."""

    def set_up(self, subtask: Subtask, checkpoint: str, *, setup: str = "") -> None:
        """The scene is already laid out by the fake rig's simulator."""

    def judge(self, subtask: Subtask, checkpoint: str, *, success: str = "") -> bool | None:
        return None  # the simulator's checker (sim_checker) is the run's only judge


def _stdin_is_a_terminal() -> bool:
    try:
        return sys.stdin is not None and sys.stdin.isatty()
    except (AttributeError, ValueError):  # replaced by an object without isatty, or closed
        return False
