"""``pilworld policy serve``: serve a local policy in openpi's websocket format.

Any openpi client (or :class:`~pilworld.policies.openpi.client.OpenPiClient`) can then drive it, e.g. a
scripted checkpoint of the simulated rig standing in for a VLA server. Loopback only unless
``--allow-remote``; ``--max-seconds`` bounds the run (tests, scripted demos).
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path
from typing import Any

from simrig.files import SIM_RIG


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser("policy", help="serve a policy over openpi's websocket protocol")
    cmds = p.add_subparsers(dest="policy_command", metavar="COMMAND")
    cmds.required = True

    s = cmds.add_parser("serve", help="serve a scripted checkpoint on ws://HOST:PORT (openpi wire format)")
    s.add_argument("--checkpoint", default="scripted_step_30k", help="scripted checkpoint (default scripted_step_30k)")
    s.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config (default: the simulated rig)")
    s.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    s.add_argument("--port", type=int, default=8000, help="port (default 8000, openpi's; 0 = any free port)")
    s.add_argument("--seed", type=int, default=0, help="the policy's seed until a client resets it (default 0)")
    s.add_argument("--horizon", type=int, default=50, help="actions per chunk H_π (default 50)")
    s.add_argument("--max-seconds", type=float, default=None, help="stop after this many seconds (default: never)")
    s.add_argument(
        "--allow-remote", action="store_true", help="allow a non-loopback --host (the protocol has no authentication)"
    )
    s.set_defaults(handler=_serve)


def _serve(args: argparse.Namespace) -> int:
    from pilworld.config.rig import RigConfig
    from pilworld.policies.openpi.server import PolicyServer
    from pilworld.policies.scripted import CHECKPOINTS, ScriptedPolicy

    names = [c.name for c in CHECKPOINTS]
    if args.checkpoint not in names:
        raise ValueError(f"--checkpoint: unknown {args.checkpoint!r}; expected one of {', '.join(names)}")
    if not 1 <= args.horizon <= 10_000:
        raise ValueError(f"--horizon: expected an integer in 1..10,000 (actions per chunk), got {args.horizon}")
    if not 0 <= args.port <= 65535:
        raise ValueError(f"--port: expected 0..65535, got {args.port}")
    if args.max_seconds is not None and not args.max_seconds > 0:
        raise ValueError(f"--max-seconds: expected a positive number, got {args.max_seconds}")
    rig = RigConfig.load(args.rig)
    policy = ScriptedPolicy(rig, args.checkpoint, seed=args.seed, horizon=args.horizon)
    size = (rig.image_size.height, rig.image_size.width)
    server = PolicyServer(
        policy,
        args.host,
        args.port,
        metadata={"rig": rig.name, "action_horizon": args.horizon},
        image_size=size,
        allow_remote=args.allow_remote,
    )
    try:
        server.__enter__()
    except OSError as err:  # the port is taken (or the address is not this machine's)
        raise ValueError(f"--port: cannot listen on {args.host}:{args.port} ({err.strerror or err})") from None
    with contextlib.ExitStack() as stack:
        stack.push(server.__exit__)
        limit = "" if args.max_seconds is None else f" for {args.max_seconds:g} s"
        print(
            f"policy serve: {policy.name} on {server.url} (GET /healthz), images {size[0]}×{size[1]} CHW, "
            f"chunks {args.horizon}×14{limit}; Ctrl-C stops",
            flush=True,
        )
        deadline = None if args.max_seconds is None else time.monotonic() + args.max_seconds
        while deadline is None or time.monotonic() < deadline:
            time.sleep(0.1 if deadline is None else min(0.1, max(0.0, deadline - time.monotonic())))
    print("policy serve: stopped", file=sys.stderr)
    return 0
