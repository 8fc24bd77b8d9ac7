"""``pilworld bench <name>``: performance figures as JSON (never timed assertions in tests).

Every benchmark prints a human summary and, with ``--json``, one JSON object as its last line.

One benchmark, one module: each :class:`Bench` names a module of :mod:`pilworld.bench` that offers
``add_arguments(parser)`` and ``run(args) -> int``; this file only lists them, in the order of
``pilworld bench --help``. A bench's module is imported when its name is on the command line, just before
its options are parsed (``--help`` included): the benches pull in torch, MuJoCo and the world models,
which every other ``pilworld`` command starts without.
"""

from __future__ import annotations

import argparse
import importlib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any


@dataclass(frozen=True)
class Bench:
    name: str  # the subcommand
    module: str  # under pilworld.bench
    help: str


BENCHES = (
    Bench(
        "control-video",
        "control_video",
        "Γ / Γ⁺ speed: marker frames per second, or one Γ⁺ chunk's latency beside the world model's",
    ),
    Bench(
        "robot-render",
        "robot_render",
        "Γ⁺ robot render vs MuJoCo's segmentation of the full simulated scene: IoU per view",
    ),
    Bench(
        "reprojection",
        "reprojection",
        "Γ⁺ scene prior vs the frozen frame on held-out clips: PSNR per view at k = 1, 5, 10, 15",
    ),
    Bench("data", "data", "episode store write/read frames per second and clip loader rate"),
    Bench("sim", "sim", "simulated rig: physics steps/s, render ms/view, realtime factor, success rates"),
    Bench(
        "calibration",
        "calibration",
        "calibration: intrinsics and hand-eye accuracy, hand-eye stability sweep per method (chart PNG)",
    ),
    Bench("paired-timing", "paired_timing", "wall time per paired subtask, real and imagined branch separately"),
    Bench(
        "paired",
        "paired",
        "the paper's table: SR_real, SR_imag, |ΔSR|, HFR, Pearson/MMRV for ours, the baseline, ablations",
    ),
    Bench(
        "speed-accuracy",
        "speed_accuracy",
        "v1 presets × resolution × sampling steps, and v2: one round's latency vs closed-loop |ΔSR| and HFR",
    ),
    Bench(
        "stability",
        "stability",
        "per model: horizon sweep, failure faithfulness, counterfactuals, calibration/mount/robot-model errors, "
        "OOD actions, action shuffle",
    ),
    Bench("judges", "judges", "image-only success judge vs the simulator's checker on a dataset"),
    Bench("drivers", "drivers", "hardware drivers against the protocol fakes: servo rate, bus round trips, camera fps"),
    Bench(
        "ppi",
        "ppi",
        "PPI++ intervals on the simulated rig: coverage, widths vs the variance formula, effective sample size",
    ),
    Bench("hallucination", "hallucination", "hallucination detector on injected faults and clean episodes"),
    Bench("world-model-presets", "world_model_presets", "parameter counts and chunk latency of every native preset"),
    Bench(
        "world-model",
        "world_model",
        "world model: single-step PSNR/SSIM on held-out sim episodes vs the frozen baseline, chunk latency",
    ),
    Bench(
        "chunk-latency",
        "chunk_latency",
        "one imagined round (control video + prediction + state) per world model, round-robin",
    ),
    Bench(
        "wm-ladder",
        "wm_ladder",
        "diagnostic ladder: state contract, autoencoded frames, judge fairness, teacher-forced vs free PSNR",
    ),
)
_BY_NAME = {b.name: b for b in BENCHES}

if TYPE_CHECKING:
    _SubParsers = argparse._SubParsersAction[argparse.ArgumentParser]
else:
    _SubParsers = argparse._SubParsersAction  # not subscriptable at run time


class _Benches(_SubParsers):
    """The bench subcommands: the chosen one's module adds its options just before argparse reads them."""

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: str | Sequence[Any] | None,
        option_string: str | None = None,
    ) -> None:
        name = str(values[0]) if isinstance(values, list) and values else ""  # argparse passes [NAME, *rest]
        if name in _BY_NAME:
            _load(self._name_parser_map[name], _BY_NAME[name])
        super().__call__(parser, namespace, values, option_string)


def _load(parser: argparse.ArgumentParser, bench: Bench) -> None:
    if parser.get_default("handler") is None:  # once per parser
        module = importlib.import_module(f"pilworld.bench.{bench.module}")
        module.add_arguments(parser)
        parser.set_defaults(handler=module.run)


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser("bench", help="run a benchmark and print JSON")
    benches = p.add_subparsers(dest="bench", metavar="NAME", action=_Benches)
    benches.required = True
    for bench in BENCHES:
        benches.add_parser(bench.name, help=bench.help)
