"""Fault injection shared by the protocol fakes: a test switches a fault on, the fake misbehaves.

Kinds (each fake documents which it supports and how it behaves):

* ``drop``     — requests are silently ignored (no reply), with probability ``rate`` (default 1);
* ``corrupt``  — replies are sent with a corrupted byte (bad checksum / broken frame), same ``rate``;
* ``stall``    — the device stops talking altogether (a stream stops, nothing is answered) but stays
  connected;
* ``disconnect`` — the connection is closed (socket closed, pty hung up);
* ``protective_stop`` / ``emergency_stop`` — UR controller safety stops (reported in the safety bits).
"""

from __future__ import annotations

import random
import threading
from dataclasses import dataclass

FAULT_KINDS = ("drop", "corrupt", "stall", "disconnect", "protective_stop", "emergency_stop")


@dataclass(frozen=True)
class Fault:
    kind: str
    rate: float = 1.0

    def __post_init__(self) -> None:
        if self.kind not in FAULT_KINDS:
            raise ValueError(f"fault: expected one of {FAULT_KINDS}, got {self.kind!r}")
        if not 0.0 < self.rate <= 1.0:
            raise ValueError(f"rate: expected 0 < rate <= 1, got {self.rate}")


class FaultSwitch:
    """The faults currently injected into one fake device (thread-safe)."""

    def __init__(self, seed: int = 0) -> None:
        self._faults: dict[str, Fault] = {}
        self._lock = threading.Lock()
        self._rng = random.Random(seed)

    def inject(self, kind: str, rate: float = 1.0) -> None:
        fault = Fault(kind, rate)
        with self._lock:
            self._faults[kind] = fault

    def clear(self, kind: str | None = None) -> None:
        with self._lock:
            if kind is None:
                self._faults.clear()
            else:
                self._faults.pop(kind, None)

    def active(self, kind: str) -> bool:
        """Whether ``kind`` is injected (and, for a rate below 1, whether it strikes this time)."""
        with self._lock:
            fault = self._faults.get(kind)
            if fault is None:
                return False
            return fault.rate >= 1.0 or self._rng.random() < fault.rate
