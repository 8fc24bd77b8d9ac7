"""The shared-memory layout between a :class:`~hw_drivers.ur.arm.URArm` and its worker process.

Three raw float64 arrays (no locks: a reader must never block the 500 Hz loop):

* ``state`` (worker → parent): a seqlock-protected snapshot — odd ``SEQ`` while the worker writes, so the
  parent retries a torn read;
* ``target`` (parent → worker): the latest joint target, its mode and speed cap, under the same seqlock;
* ``ring``: the last ``RING`` loop periods [s] for :meth:`URArm.servo_stats` (a torn entry only blurs a
  statistic, so no seqlock).

``time.monotonic()`` is CLOCK_MONOTONIC, the same clock in every process, so timestamps compare directly.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

# state slots
SEQ, T_FRESH, Q, QD = 0, 1, slice(2, 8), slice(8, 14)
SAFETY_BITS, RUNTIME_STATE, ROBOT_MODE, STATUS, HEARTBEAT = 14, 15, 16, 17, 18
CYCLES, STATS_T0, MISSED, RING_WRITES = 19, 20, 21, 22
SETPOINT = slice(23, 29)
STATE_SIZE = 29

# target slots
T_SEQ, T_MODE, T_SPEED, T_Q, T_STATS_RESET = 0, 1, 2, slice(3, 9), 9
TARGET_SIZE = 10
HOLD, TRACK = 0.0, 1.0

RING = 10_000  # 20 s of periods at 500 Hz

# worker status codes (STATUS slot)
OK, STARTING, PROTECTIVE_STOP, EMERGENCY_STOP, SAFETY_STOP = 0, 1, 2, 3, 4
CONNECTION_LOST, STREAM_TIMEOUT, PROTOCOL_ERROR, SCRIPT_STOPPED, CLOSED = 5, 6, 7, 8, 9

# safety_status_bits (ur_rtde's SafetyStatus enum) and their names in ArmState.safety
SAFETY_BIT_NAMES = (  # most severe first
    (5, "emergency_stop"),  # system emergency stop
    (6, "emergency_stop"),  # robot emergency stop
    (7, "emergency_stop"),
    (2, "protective_stop"),
    (4, "safeguard_stop"),
    (8, "violation"),
    (9, "fault"),
    (3, "recovery"),
    (1, "reduced"),
    (0, "normal"),
)
EMERGENCY_MASK = (1 << 5) | (1 << 6) | (1 << 7)
PROTECTIVE_MASK = 1 << 2
OTHER_STOP_MASK = (1 << 3) | (1 << 4) | (1 << 8) | (1 << 9)
PLAYING = 2  # runtime_state
ROBOT_RUNNING = 7  # robot_mode


def decode_safety(bits: int) -> str:
    """The most severe condition in ``safety_status_bits`` ("normal", "protective_stop", …; "unknown" if none)."""
    for bit, name in SAFETY_BIT_NAMES:
        if bits & (1 << bit):
            return name
    return "unknown"


def view(raw: Any) -> NDArray[np.float64]:
    """A numpy view of a ``multiprocessing`` RawArray('d')."""
    return np.frombuffer(raw, dtype=np.float64)


def seq_write(arr: NDArray[np.float64], values: list[tuple[int | slice, Any]]) -> None:
    arr[SEQ] += 1  # odd: writing
    for key, value in values:
        arr[key] = value
    arr[SEQ] += 1


def seq_read(arr: NDArray[np.float64], timeout: float = 0.05) -> NDArray[np.float64]:
    """A consistent copy of ``arr`` (retrying while the writer is mid-update)."""
    deadline = time.monotonic() + timeout
    while True:
        before = arr[SEQ]
        snapshot = arr.copy()
        if before % 2 == 0 and arr[SEQ] == before:
            return snapshot
        if time.monotonic() > deadline:
            return snapshot  # a writer stuck mid-update is dead: the heartbeat check reports it
        time.sleep(0)


@dataclass(frozen=True)
class WorkerConfig:
    name: str
    host: str
    servo_rate_hz: float
    lookahead_time: float
    gain: float
    max_joint_speed: float
    watchdog_hz: float
    stream_timeout: float
    attempts: int
    retry_delay: float


@dataclass(frozen=True)
class ServoStats:
    """Timing of the servo loop since the last reset (``URArm.reset_servo_stats``)."""

    rate_hz: float  # completed cycles / wall time
    period_p50_ms: float
    period_p99_ms: float
    period_max_ms: float
    missed_periods: int  # periods longer than 1.5 × nominal
    cycles: int
    window_s: float
