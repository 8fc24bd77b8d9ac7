"""``pilworld robot check``: connect to every device of a rig, read each once, print a health table."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser("robot", help="hardware: check a rig's devices")
    cmds = p.add_subparsers(dest="robot_command", metavar="COMMAND")
    cmds.required = True
    c = cmds.add_parser(
        "check",
        help="connect to every arm, gripper and camera of a rig, read each once, print a health table",
        description="Each device is checked on its own (one failure does not hide the others). A rig file with a "
        "'hardware.fake' section (configs/rig/fake_dual_ur5e.yaml) starts the protocol fakes first. Exit status 0 "
        "when every device answered, 1 otherwise.",
    )
    c.add_argument("--rig", type=Path, required=True, help="rig file with a 'hardware:' section")
    c.add_argument("--json", action="store_true", help="print the report as one JSON object on the last line")
    c.set_defaults(handler=_check)


def _check(args: argparse.Namespace) -> int:
    from hw_drivers.check import check_robot, format_table, report_json
    from hw_drivers.fakes.rig import FakeRig
    from pilworld.config.rig import RigConfig

    hardware = RigConfig.load(args.rig).hardware
    if hardware is not None and hardware.fake is not None:  # the protocol fakes first, then the same checks
        with FakeRig(args.rig) as fake:
            report = check_robot(args.rig, fake.endpoints)
    else:
        report = check_robot(args.rig)
    print(format_table(report))
    if args.json:
        print(json.dumps(report_json(report)))
    return 0 if all(d.ok for d in report) else 1
