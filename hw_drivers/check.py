"""``pilworld robot check``: connect to every device of a rig, read it once, report, disconnect.

Each device is checked on its own, so one unplugged gripper does not hide the state of the others:
the report lists every part with what it read (or the typed error it raised) and how long that took.
On a rig file with ``hardware.fake`` the protocol fakes are started first and stopped at the end.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pilworld.config.rig import RigConfig

if TYPE_CHECKING:  # the fakes sit above the drivers; a caller that starts them passes their endpoints
    from hw_drivers.fakes.rig import FakeEndpoints


@dataclass(frozen=True)
class DeviceHealth:
    device: str  # "left arm", "right gripper", "cam_high"
    driver: str  # ur_rtde | dynamixel | robotiq | opencv
    address: str  # host, serial port or camera source
    ok: bool
    reading: str  # what was read, or the error (type: message)
    seconds: float  # connect + one reading


def _probe(device: str, driver: str, address: str, part: Any, read: Callable[[Any], str]) -> DeviceHealth:
    t0 = time.monotonic()
    try:
        part.connect()
        try:
            reading = read(part)
        finally:
            part.disconnect()
        return DeviceHealth(device, driver, address, True, reading, time.monotonic() - t0)
    except Exception as e:  # reported, not raised: the table shows every device
        return DeviceHealth(device, driver, address, False, f"{type(e).__name__}: {e}", time.monotonic() - t0)


def _arm_reading(arm: Any) -> str:
    s = arm.state(max_age=1.0)
    q = ", ".join(f"{v:+.3f}" for v in np.asarray(s.q))
    return f"q = [{q}] rad, safety {s.safety}"


def _gripper_reading(gripper: Any) -> str:
    deadline = time.monotonic() + 2.0
    while True:  # the I/O thread's first reading may still be on its way
        try:
            s = gripper.status(max_age=1.0)
            break
        except Exception:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)
    fault = f", fault {s.fault}" if s.fault else ""
    return f"opening {s.opening:.3f}{', object detected' if s.object_detected else ''}{fault}"


def _camera_reading(camera: Any) -> str:
    frame = camera.read_latest(max_age=1.0)
    h, w = frame.image.shape[:2]
    return f"{w}x{h} frame, {1000 * (time.monotonic() - frame.timestamp):.0f} ms old"


def check_robot(rig_path: str | Path, endpoints: FakeEndpoints | None = None) -> list[DeviceHealth]:
    """One :class:`DeviceHealth` per arm, gripper and camera of the rig file. ``endpoints``: where the
    protocol fakes of a fake rig listen (the caller starts them; ``auto`` ports and sources resolve there)."""
    from hw_drivers.factory import build_arms, build_cameras, build_grippers, camera_source, gripper_port

    rig = RigConfig.load(rig_path)
    if rig.hardware is None:
        raise ValueError(
            f"{rig_path}: rig {rig.name!r} has no 'hardware:' section (a simulated rig has no devices to check)"
        )
    hw = rig.hardware
    report: list[DeviceHealth] = []
    arms = build_arms(rig, endpoints)
    for side, arm in arms.items():
        report.append(_probe(f"{side} arm", "ur_rtde", getattr(arm, "host", ""), arm, _arm_reading))
    grippers = build_grippers(rig, endpoints)
    for side, gripper in grippers.items():
        cfg = getattr(hw.grippers, side)
        port = gripper_port(rig, side, endpoints)
        report.append(_probe(f"{side} gripper", cfg.driver, port, gripper, _gripper_reading))
    for name, camera in build_cameras(rig, endpoints).items():
        source = str(camera_source(rig, name, endpoints))
        report.append(_probe(name, "opencv", source, camera, _camera_reading))
    return report


def format_table(report: list[DeviceHealth]) -> str:
    rows = [f"{'device':<16} {'driver':<10} {'status':<6} {'time':>7}  address / reading"]
    for d in report:
        rows.append(f"{d.device:<16} {d.driver:<10} {'ok' if d.ok else 'FAIL':<6} {d.seconds:>6.2f}s  {d.address}")
        rows.append(f"{'':<43}{d.reading}")
    bad = sum(not d.ok for d in report)
    rows.append(f"{len(report) - bad} of {len(report)} devices ok")
    return "\n".join(rows)


def report_json(report: list[DeviceHealth]) -> dict[str, Any]:
    return {"ok": all(d.ok for d in report), "devices": [asdict(d) for d in report]}
