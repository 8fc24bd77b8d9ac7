"""``pilworld bench stability``: where world models fail — long horizons, failures, counterfactuals, bad inputs.

Several world models side by side (default: the shipped v2 ``pilworld`` and the paper-faithful
``v2_paper_gamma``, names from :mod:`pilworld.bench.variants`) on the simulated rig:

1. **Horizon sweep** — one paired protocol with R = 20 rounds (layouts from seed 7,000,000, reserved),
   every model on the same pairs (:func:`~pilworld.bench.variants.evaluate_variants`: the real branches
   run once and are shared), judged by the image-only judge. HFR at horizon R ∈ {1, 2, 5, 10, 20} is the
   mean over imagined episodes of min(t_h, T_R) / T_R with T_R = 1 + R·K frames (t_h: the automatic
   detector's first hallucination frame on the 20-round episode; the detector looks at most a few frames
   ahead, so a truncated episode would give the same t_h below T_R). Per-round error: head-view PSNR
   between the imagined and real frame at the end of each round, beside the start frame held still
   ("frozen").
2. **Failure faithfulness** — on pairs whose real branch failed, the share whose imagined branch failed
   too (video models tend to "repair" failures); and the converse on real successes.

The probes start from 3 tasks × 2 checkpoints × ``starts`` subtasks (layouts from seed 7,000,500). Each
chunk is executed on the simulator once per start and imagined by every model from the same start,
through the same safety filter (a refused chunk is listed in ``refused`` and left out):

3. **Counterfactual divergence** — the policy's chunk, "hold" (stand still) and "reverse" (the policy's
   displacement mirrored), one round each. For policy vs hold and policy vs reverse, the model's two
   futures differ by MSE_pred and the simulator's by MSE_real; ``ratio`` = median over starts of
   MSE_pred / MSE_real (1: the model separates the futures as much as reality does; 0: it ignores the
   action).
4. **Calibration and mount errors** — the policy's chunk imagined with a wrong calibration *given to the
   model* (the simulator keeps the true rig): the head camera's principal point moved 5, 10, 20 px
   (diagonally, of 128); the head camera's extrinsics off by (2 mm, 0.2°), (5 mm, 0.5°), (10 mm, 1°); each
   wrist camera's mount off by (2 mm, 0.5°), (5 mm, 1°) (directions from
   :func:`~pilworld.control_video.probes.perturbed_cameras` with seed ``ERROR_SEED``). A model that
   composites the rig's geometry (v2, ``bind_rig``) is bound to the wrong rig
   (:func:`~pilworld.control_video.probes.perturbed_rig`: its layers, tracked objects and their drawing
   use the wrong cameras); every model's control video Γ (the markers) is drawn through the wrong head
   camera. A model without ``bind_rig`` gets only the Γ change (wrist errors do not reach it).
5. **Robot-model mismatch** — the same, with the robot model rendered by the model's layers wrong: link
   radii ×0.8, ×1.2, every robot geom coloured (0.8, 0.3, 0.3, 1) (models with ``bind_rig`` only).
   For 4 and 5: single-round PSNR per view against the simulator, and its change from the right rig.
6. **Out-of-distribution actions** — arm motions the training data never had ("fast": displacement ×3,
   each step's increment capped at 0.1 rad — about the joints' top speed, "jitter": N(0, 0.05 rad) per
   step, "offset": +0.3 rad on both shoulder lifts, ramped in), each executed in both branches through the
   same safety filter (which slows them to the joints' speed caps): single-round PSNR per view against
   the simulator, beside the policy's chunk.
7. **Action shuffle** (cross-episode) — for ``SHUFFLE_ROUNDS`` = 2 rounds, another episode's chunks
   transplanted onto this start: the donor is the same task, checkpoint and subtask on layout seed
   + ``DONOR_SEED_OFFSET`` (its policy's first chunk, then the chunk it computes after that chunk ran on
   the simulator); arm columns = this branch's state + the donor chunk's displacement from the donor's
   state, grippers = the donor's commands. Executed on the simulator and imagined by every model, beside
   the policy's own two chunks (the second computed from the simulator's frame after the first, fed to
   both). Per view: divergence (MSE between the own and the shuffled futures, model vs simulator: the
   median ratio and the share of starts where the model's futures differ at all — "a different
   future"); consistency (PSNR of the model's shuffled future against the simulator's, beside the same
   for the own chunks — "a consistent future"); determinism (the shuffled chunks imagined twice with the
   same seed give identical frames).

The probes run in a spawned process of their own beside the horizon runs (``workers=1``: one after the
other); every figure is the same either way.

Seeds: horizon layouts from ``STABILITY_SEED0`` = 7,000,000, probe layouts from ``PROBE_SEED0`` =
7,000,500 (the policy and model seed of each start is its pair seed), donors at + ``DONOR_SEED_OFFSET``,
the jitter noise from ``numpy.random.default_rng(PROBE_SEED0)`` in start order, the directions of the
camera errors from ``ERROR_SEED``.

The package follows the probes: seeds and shared names (:mod:`.settings`), frame errors (:mod:`.metrics`),
the horizon figures (:mod:`.horizon`), the probes' chunks (:mod:`.probe_chunks`), the wrong rigs
(:mod:`.rig_errors`), the models (:mod:`.models`), the probes (:mod:`.prober`) and their summary
(:mod:`.summary`), the whole bench (:mod:`.runner`) and its printed summary (:mod:`.report`); this module
adds ``pilworld bench stability``'s options and run.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pilworld.bench.flags import add_json, add_rig, run_folder
from pilworld.bench.output import emit
from pilworld.bench.stability.horizon import horizon_sweep
from pilworld.bench.stability.models import known_models, resolve_models
from pilworld.bench.stability.probe_chunks import JITTER_RAD, transplant
from pilworld.bench.stability.prober import probe
from pilworld.bench.stability.report import summary_lines
from pilworld.bench.stability.rig_errors import (
    CAL_SHIFTS_PX,
    ERROR_SEED,
    HEAD_ERRORS,
    ROBOT_ERRORS,
    WRIST_ERRORS,
    RigError,
    rig_errors,
)
from pilworld.bench.stability.runner import run_stability
from pilworld.bench.stability.settings import (
    DEFAULT_MODELS,
    DONOR_SEED_OFFSET,
    HORIZONS,
    PROBE_SEED0,
    SHUFFLE_ROUNDS,
    STABILITY_SEED0,
)
from pilworld.options.bounds import at_least_one
from pilworld.options.parse import parse_list

__all__ = [
    "CAL_SHIFTS_PX",
    "DEFAULT_MODELS",
    "DONOR_SEED_OFFSET",
    "ERROR_SEED",
    "HEAD_ERRORS",
    "HORIZONS",
    "JITTER_RAD",
    "PROBE_SEED0",
    "ROBOT_ERRORS",
    "SHUFFLE_ROUNDS",
    "STABILITY_SEED0",
    "WRIST_ERRORS",
    "RigError",
    "horizon_sweep",
    "known_models",
    "probe",
    "resolve_models",
    "rig_errors",
    "run_stability",
    "summary_lines",
    "transplant",
]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--quick", action="store_true", help="1 subtask per task × checkpoint, 1 probe start each")
    parser.add_argument(
        "--models",
        default="",
        help="bench variants side by side, comma-separated (default: pilworld,v2_paper_gamma)",
    )
    add_rig(parser)
    parser.add_argument(
        "--subtasks", type=int, default=None, help="20-round pairs per task × checkpoint (default 1 / 5)"
    )
    parser.add_argument("--starts", type=int, default=None, help="probe starts per task × checkpoint (default 1 / 4)")
    parser.add_argument("--out", type=Path, default=None, help="run folders (default bench_runs/stability-quick|full)")
    parser.add_argument("--workers", type=int, default=None, help="judging processes (default: one per CPU)")
    parser.add_argument("--chart", type=Path, default=None, help="PNG to draw (default OUT/stability.png)")
    add_json(parser)


def run(args: argparse.Namespace) -> int:
    """The whole bench for ``--models``, its chart (``--chart``, default OUT/stability.png) and the summary."""
    # Imported here: the chart needs matplotlib, which the probes' spawned process does not.
    from pilworld.bench.charts import stability_chart

    at_least_one(args, "subtasks", "starts")
    out = run_folder(args, "stability")
    r = run_stability(
        rig=args.rig,
        quick=args.quick,
        out=out,
        subtasks=args.subtasks,
        starts=args.starts,
        workers=args.workers,
        models=parse_list(args.models) or None,
        progress=not args.json,
    )
    r["chart"] = str(stability_chart(r, args.chart or out / "stability.png"))
    return emit(args, r, summary_lines(r))
