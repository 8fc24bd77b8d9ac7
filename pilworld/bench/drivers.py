"""``pilworld bench drivers``: the hardware drivers' timing against the protocol fakes.

The whole robot runs as in a real branch: a :class:`~hw_drivers.dual_arm.DualArmRobot` built from the
fake rig (``configs/rig/fake_dual_ur5e.yaml``) is commanded at the control rate with a slow joint
sine while it is observed every Δ steps, for ``seconds``. Meanwhile the UR arms' servo loops, the
grippers' I/O threads and the cameras' capture threads run as they would on hardware. Reported:

* ``servo_rate_hz`` (each arm and the minimum) and ``servo_period_p99_ms`` — the 500 Hz servoJ loop;
* ``dynamixel_roundtrip_ms`` / ``robotiq_roundtrip_ms`` — median of a polling read on the bus (p99 too);
* ``camera_fps`` — frames received per second per camera (the fake serves ``hardware.fake.camera_fps``);
* ``control_period_p99_ms`` — how evenly the control loop itself kept its period;
* ``gripper_set_target_p99_ms`` / ``camera_read_latest_p99_ms`` — what the caller of a driver pays: a
  gripper's ``set_target`` and a camera's ``read_latest`` are meant never to wait on I/O (their tests check
  that as an ordering against a stalled bus; the times are measured here), each over ``CALLS`` calls.

The fakes do not model wire time (a real RS-485 round trip adds ~1–2 ms plus the adapter's latency
timer), so the gripper figures are the drivers' own overhead.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from pilworld.bench.common import machine_info
from pilworld.bench.flags import add_json
from pilworld.bench.output import emit
from pilworld.types import ARM_LAYOUT

FAKE_RIG = Path(__file__).resolve().parents[2] / "configs" / "rig" / "fake_dual_ur5e.yaml"
CALLS = 200  # calls timed per gripper set_target / camera read_latest


def _call_ms(call: Callable[[], object]) -> dict[str, float]:
    """Median and p99 of CALLS calls of ``call``, in ms (1 ms apart, as a control loop would call it)."""
    times = []
    for _ in range(CALLS):
        t0 = time.perf_counter()
        call()
        times.append(time.perf_counter() - t0)
        time.sleep(0.001)
    ms = np.asarray(times) * 1000
    return {"median_ms": round(float(np.median(ms)), 4), "p99_ms": round(float(np.percentile(ms, 99)), 4)}


def _finite(x: float) -> float | None:
    return None if not math.isfinite(x) else round(float(x), 3)


def run_drivers_bench(
    rig_path: str | Path = FAKE_RIG, seconds: float = 10.0, *, progress: bool = False
) -> dict[str, Any]:
    from hw_drivers.factory import build_robot
    from hw_drivers.fakes.rig import FakeRig
    from pilworld.config.rig import RigConfig

    if seconds <= 0:
        raise ValueError(f"seconds: expected > 0, got {seconds}")
    rig = RigConfig.load(rig_path)
    if rig.hardware is None or rig.hardware.fake is None:
        raise ValueError(f"{rig_path}: the drivers bench needs a rig file with a 'hardware.fake' section")
    with FakeRig(rig_path) as fake:
        robot = build_robot(rig, fake.endpoints)
        with robot:
            q0 = robot.observe().state.astype(np.float64)
            for arm in robot.arms.values():
                arm.reset_servo_stats()  # type: ignore[attr-defined]
            period = 1.0 / rig.control_rate_hz
            periods: list[float] = []
            t0 = t_prev = time.monotonic()
            t_next = t0
            step = 0
            bar = tqdm(total=round(seconds), desc="drivers bench", unit="s", disable=not progress)
            while (now := time.monotonic()) - t0 < seconds:
                if now < t_next:
                    time.sleep(t_next - now)
                t_next += period
                t = time.monotonic()
                periods.append(t - t_prev)
                t_prev = t
                a = q0.copy()
                a[[0, 7]] += 0.1 * math.sin(2 * math.pi * 0.25 * (t - t0))  # a slow sweep of both bases
                robot.send_action(a)
                step += 1
                if step % 3 == 0:
                    robot.observe()
                bar.n = min(round(seconds), int(t - t0))
                bar.refresh()
            bar.close()
            servo = {side: arm.servo_stats() for side, arm in robot.arms.items()}  # type: ignore[attr-defined]
            grippers: dict[str, Any] = {}
            for side, g in robot.grippers.items():
                rt = g.roundtrip_ms()  # type: ignore[attr-defined]
                driver = getattr(rig.hardware.grippers, side).driver
                grippers[driver] = {"side": side, "median_ms": _finite(rt.median_ms), "p99_ms": _finite(rt.p99_ms)}
            fps = {name: round(cam.fps_measured(), 2) for name, cam in robot.cameras.items()}  # type: ignore[attr-defined]
            held = robot.observe().state
            set_target = {
                side: _call_ms(lambda g=g, o=float(held[ARM_LAYOUT[side][1]]): g.set_target(o))  # type: ignore[misc]
                for side, g in robot.grippers.items()
            }
            read_latest = {
                name: _call_ms(lambda c=cam: c.read_latest(1.0))  # type: ignore[misc]
                for name, cam in robot.cameras.items()
            }
    p = np.asarray(periods[1:]) * 1000
    return {
        "rig": str(rig_path),
        "seconds": seconds,
        "servo_rate_target_hz": rig.hardware.arms.left.servo_rate_hz,
        "servo_rate_hz": round(min(s.rate_hz for s in servo.values()), 2),
        "servo_period_p99_ms": round(max(s.period_p99_ms for s in servo.values()), 3),
        "servo": {
            side: {
                "rate_hz": round(s.rate_hz, 2),
                "period_p50_ms": round(s.period_p50_ms, 3),
                "period_p99_ms": round(s.period_p99_ms, 3),
                "period_max_ms": round(s.period_max_ms, 3),
                "missed_periods": s.missed_periods,
                "cycles": s.cycles,
            }
            for side, s in servo.items()
        },
        "dynamixel_roundtrip_ms": grippers.get("dynamixel", {}).get("median_ms"),
        "robotiq_roundtrip_ms": grippers.get("robotiq", {}).get("median_ms"),
        "grippers": grippers,
        "camera_fps": round(min(fps.values()), 2),
        "camera_fps_per_camera": fps,
        "camera_fps_served": rig.hardware.fake.camera_fps,
        "control_rate_hz": rig.control_rate_hz,
        "control_period_p50_ms": round(float(np.percentile(p, 50)), 3) if p.size else None,
        "control_period_p99_ms": round(float(np.percentile(p, 99)), 3) if p.size else None,
        "gripper_set_target_p99_ms": max(v["p99_ms"] for v in set_target.values()) if set_target else None,
        "gripper_set_target": set_target,
        "camera_read_latest_p99_ms": max(v["p99_ms"] for v in read_latest.values()) if read_latest else None,
        "camera_read_latest": read_latest,
        "machine": machine_info(),
    }


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--rig", type=Path, default=None, help="rig file with a hardware.fake section (default: the fake rig)"
    )
    parser.add_argument("--seconds", type=float, default=10.0, help="how long the robot is driven (default 10)")
    add_json(parser)


def run(args: argparse.Namespace) -> int:
    r = run_drivers_bench(args.rig or FAKE_RIG, args.seconds, progress=not args.json)
    line = (
        f"drivers: servo {r['servo_rate_hz']} Hz (target {r['servo_rate_target_hz']}), p99 period "
        f"{r['servo_period_p99_ms']} ms; round trips: dynamixel {r['dynamixel_roundtrip_ms']} ms, "
        f"robotiq {r['robotiq_roundtrip_ms']} ms; cameras {r['camera_fps']} fps (served {r['camera_fps_served']})"
        f"; calls (p99): gripper set_target {r['gripper_set_target_p99_ms']} ms, "
        f"camera read_latest {r['camera_read_latest_p99_ms']} ms"
    )
    return emit(args, r, [line])
