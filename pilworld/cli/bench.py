"""``pilworld bench <name>``: performance figures as JSON (never timed assertions in tests).

Every benchmark prints a human summary and, with ``--json``, one JSON object as its last line.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from pilworld.bench.output import Column, emit, num, pct, table
from pilworld.bench.reprojection import add_arguments as reprojection_arguments
from pilworld.collection.tasks import APPEARANCES
from pilworld.control_video.robot_render import BACKENDS
from pilworld.control_video.styles import STYLES, Style
from pilworld.options.bounds import SIM_REPEATS, bounded
from pilworld.options.parse import parse_names as _names
from pilworld.options.parse import parse_size
from pilworld.types import ChunkSpec
from simrig.files import SIM_RIG


def _signed(digits: int) -> Any:
    return lambda x: f"{float(x):+.{digits}f}"


# The tables the benches print, one column list each (pilworld/bench/output.py aligns them).
PAIRED_COLUMNS = (
    Column("variant", 15, "variant", align="<"),
    Column("SR_real", 8, "sr_real", pct),
    Column("SR_imag", 8, "sr_imag", pct),
    Column("|ΔSR|", 7, "abs_delta_sr", pct),
    Column("HFR", 6, "hfr", num),
    Column("Pearson", 8, "pearson", num),
    Column("MMRV", 6, "mmrv", num),
    Column("head PSNR", 9, lambda row: row["head"].get("psnr_pooled"), num, align="<", sep="  "),
)
SPEED_ACCURACY_COLUMNS = (
    Column("point", 14, "id", align="<"),
    Column("params", 8, "params", lambda x: "—" if x is None else f"{x / 1e6:.2f}M"),
    Column("round ms", 10, "chunk_latency_ms", lambda x: num(x, 1)),
    Column("x realtime", 11, "realtime_factor", lambda x: num(x, 1)),
    Column("|ΔSR|", 7, "abs_delta_sr", pct),
    Column("HFR", 7, "hfr", lambda x: num(x, 3)),
    Column("SR_imag", 8, "sr_imag", pct),
    Column("head PSNR", 10, "psnr_head", num),
    Column("front", 5, "front", align="<", sep="  "),
    Column("", 0, "remark", align="<", sep=" "),
)
WORLD_MODEL_COLUMNS = (
    Column("view", 18, "view", align="<"),
    Column("psnr", 8, "psnr", num),
    Column("frozen", 8, "frozen", num),
    Column("gain", 8, "gain", _signed(2)),
    Column("pooled gain", 13, "pooled", _signed(2)),
    Column("no-hist", 9, "no_history", num),  # only when the no-history ablation ran
)
PPI_COLUMNS = (
    Column("method", 7, "method", align="<"),
    Column("predictor", 14, "predictor", align="<", sep=" "),
    Column("n", 3, "n", sep=" "),
    Column("N", 4, "N", sep=" "),
    Column("cov PPI", 8, "coverage_ppi", lambda x: num(x, 3), sep=" "),
    Column("cov cl.", 8, "coverage_classical", lambda x: num(x, 3), sep=" "),
    Column("ratio", 6, "width_ratio", lambda x: num(x, 3), sep=" "),
    Column("formula", 8, "width_ratio_formula", lambda x: num(x, 3), sep=" "),
    Column("ESS gain", 9, "ess_gain_measured", num, sep=" "),
)


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser("bench", help="run a benchmark and print JSON")
    benches = p.add_subparsers(dest="bench", metavar="NAME")
    benches.required = True

    cv = benches.add_parser(
        "control-video",
        help="Γ / Γ⁺ speed: marker frames per second, or one Γ⁺ chunk's latency beside the world model's",
    )
    cv.add_argument(
        "--style",
        default="markers",
        help=f"control-video style: {', '.join(STYLES)} (default markers, the paper's Γ: throughput bench)",
    )
    cv.add_argument("--backend", choices=BACKENDS, default="analytic", help="robot renderer (Γ⁺ styles)")
    cv.add_argument("--starts", type=int, default=4, help="Γ⁺: held-out simulated starts (default 4)")
    cv.add_argument("--chunks-per-start", type=int, default=10, help="Γ⁺: random chunks per start (default 10)")
    cv.add_argument(
        "--world-model",
        type=Path,
        default=None,
        help="Γ⁺: world-model folder timed in the same run (default: v1, sim_small); 'none' skips it",
    )
    cv.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config (default: the simulated rig)")
    cv.add_argument("--chunks", type=int, default=4000, help="random chunks per timed pass (default 4000)")
    cv.add_argument("--batch", type=int, default=64, help="chunks per render_batch call (default 64)")
    cv.add_argument("--size", default=None, help="WIDTHxHEIGHT (default: 128x128 for markers, the rig's for Γ⁺)")
    cv.add_argument("--frames", "-K", type=int, default=15, help="K (default 15)")
    cv.add_argument("--stride", type=int, default=3, help="Δ (default 3)")
    cv.add_argument("--repeats", type=int, default=3, help="timed passes; the best is reported (default 3)")
    cv.add_argument("--seed", type=int, default=0)
    cv.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    cv.set_defaults(handler=_control_video)

    rr = benches.add_parser(
        "robot-render", help="Γ⁺ robot render vs MuJoCo's segmentation of the full simulated scene: IoU per view"
    )
    rr.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config (default: the simulated rig)")
    rr.add_argument("--configs-per-arm", type=int, default=200, help="random configurations per arm (default 200)")
    rr.add_argument("--backend", choices=BACKENDS, default="analytic", help="renderer under test (default analytic)")
    rr.add_argument("--task", default="sort_cubes", help="task whose scene is the ground truth (default sort_cubes)")
    rr.add_argument("--out", type=Path, default=None, help="folder for the worst-case diagnostic PNG")
    rr.add_argument("--seed", type=int, default=0)
    rr.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    rr.set_defaults(handler=_robot_render)

    rp = benches.add_parser(
        "reprojection", help="Γ⁺ scene prior vs the frozen frame on held-out clips: PSNR per view at k = 1, 5, 10, 15"
    )
    reprojection_arguments(rp)
    rp.set_defaults(handler=_reprojection)

    dt = benches.add_parser("data", help="episode store write/read frames per second and clip loader rate")
    dt.add_argument("--episodes", type=int, default=6, help="synthetic episodes (default 6)")
    dt.add_argument("--length", type=int, default=300, help="frames per episode (default 300)")
    dt.add_argument("--size", type=int, default=128, help="image side in pixels, 3 views (default 128)")
    dt.add_argument("--video-mode", default="h264", choices=["h264", "lossless", "av1"])
    dt.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    dt.set_defaults(handler=_data)

    sm = benches.add_parser(
        "sim", help="simulated rig: physics steps/s, render ms/view, realtime factor, success rates"
    )
    sm.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config (default: the simulated rig)")
    sm.add_argument(
        "--task", default="sort_cubes", help="task (name or task file) for the speed figures (default sort_cubes)"
    )
    sm.add_argument(
        "--subtasks",
        type=int,
        default=None,
        help="also measure success rates over N subtask starts per task [1..1,000] (default: speed figures only)",
    )
    sm.add_argument(
        "--tasks",
        default="all",
        help="tasks for the success rates: names or task files, comma-separated, or all (the paper's three; default)",
    )
    sm.add_argument("--appearance", default="flat", choices=APPEARANCES, help="scene appearance (default flat)")
    sm.add_argument(
        "--baseline",
        default=None,
        choices=APPEARANCES,
        help="also time this appearance, alternating with --appearance, and report their ratios (default: none)",
    )
    sm.add_argument(
        "--repeats",
        type=int,
        default=1,
        help=bounded("speed measurements per appearance; medians reported (default 1)", SIM_REPEATS),
    )
    sm.add_argument("--checkpoints", default="all", help="comma-separated scripted checkpoints (default all)")
    sm.add_argument(
        "--workers", type=int, default=None, help="processes for the success rates (default: CPUs) [1..256]"
    )
    sm.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    sm.set_defaults(handler=_sim)

    cb = benches.add_parser(
        "calibration",
        help="calibration: intrinsics and hand-eye accuracy, hand-eye stability sweep per method (chart PNG)",
    )
    cb.add_argument("--seeds", type=int, default=20, help="intrinsics seeds, 20 views each (default 20)")
    cb.add_argument("--views", type=int, default=20, help="views per intrinsics seed (default 20)")
    cb.add_argument("--trials", type=int, default=30, help="hand-eye trials per sweep point (default 30)")
    cb.add_argument(
        "--handeye-source",
        choices=["auto", "sim", "synthetic"],
        default=None,
        help="headline hand-eye figures: rendered simulated rig (sim), synthetic, or sim when available "
        "(auto, the default; --quick defaults to synthetic)",
    )
    cb.add_argument("--handeye-poses", type=int, default=20, help="gripper poses of the headline run (default 20)")
    cb.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config of the sim hand-eye run")
    cb.add_argument("--out", type=Path, default=Path("bench_out/calibration"), help="chart folder (created)")
    cb.add_argument("--quick", action="store_true", help="2 seeds, 2 trials per point: a few seconds (tests)")
    cb.add_argument("--no-progress", action="store_true", help="no progress bars on stderr")
    cb.add_argument("--seed", type=int, default=0)
    cb.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    cb.set_defaults(handler=_calibration)

    pr = benches.add_parser("paired-timing", help="wall time per paired subtask, real and imagined branch separately")
    pr.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config (default: the simulated rig)")
    pr.add_argument("--task", default="sort_cubes", help="task (default sort_cubes)")
    pr.add_argument("--checkpoint", default="", help="policy checkpoint (default: the rig's best)")
    pr.add_argument("--subtasks", type=int, default=3, help="paired subtasks (default 3)")
    pr.add_argument("--rounds", type=int, default=5, help="closed-loop rounds per subtask (default 5)")
    pr.add_argument("--world-model", default="", help="world-model folder (default: the packaged checkpoint)")
    pr.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    pr.set_defaults(handler=_paired_timing)

    pt = benches.add_parser(
        "paired", help="the paper's table: SR_real, SR_imag, |ΔSR|, HFR, Pearson/MMRV for ours, the baseline, ablations"
    )
    pt.add_argument(
        "--quick",
        action="store_true",
        help="3 tasks × 2 checkpoints × 3 subtasks, shipped v2, paper-faithful, Ctrl-World-style",
    )
    pt.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config (default: the simulated rig)")
    pt.add_argument(
        "--out", type=Path, default=None, help="run folders (default bench_runs/paired-quick|full); resumed"
    )
    pt.add_argument(
        "--variants",
        default="",
        help="comma-separated variants (default: by mode; see docs/RESULTS.md); NAME=PATH adds a model folder",
    )
    pt.add_argument(
        "--subtasks",
        type=int,
        default=None,
        help="subtasks per task × checkpoint (default 3 quick / 8: 120 pairs per variant)",
    )
    pt.add_argument("--seed", type=int, default=None, help="first layout seed (default 6000000)")
    pt.add_argument("--workers", type=int, default=None, help="judging processes (default: one per CPU)")
    pt.add_argument(
        "--real-from", type=Path, default=None, help="copy every variant's real branches from this run folder"
    )
    pt.add_argument("--chart", type=Path, default=None, help="PNG to draw (default OUT/paired.png)")
    pt.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    pt.set_defaults(handler=_paired)

    sa = benches.add_parser(
        "speed-accuracy",
        help="v1 presets × resolution × sampling steps, and v2: one round's latency vs closed-loop |ΔSR| and HFR",
    )
    sa.add_argument(
        "--quick",
        action="store_true",
        help="steps 1,4,16, 24 held-out clips, 3 timed rounds; closed loop on 6 pairs, v1 at 1 step and v2 only",
    )
    sa.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config (default: the simulated rig)")
    sa.add_argument("--steps", default="", help="comma-separated v1 sampling steps (default 1,2,4,8,16; quick 1,4,16)")
    sa.add_argument("--clips", type=int, default=None, help="held-out clips per point (default 24 quick / 96)")
    sa.add_argument(
        "--repeats",
        type=int,
        default=None,
        help="timed imagined rounds per point; the median is reported (default 10, quick 3)",
    )
    sa.add_argument(
        "--subtasks", type=int, default=None, help="closed loop: subtasks per task × checkpoint (default 3, quick 1)"
    )
    sa.add_argument(
        "--out",
        type=Path,
        default=None,
        help="closed-loop run folders (default bench_runs/speed-accuracy-full, or -quick)",
    )
    sa.add_argument("--workers", type=int, default=None, help="judging processes (default: one per CPU)")
    sa.add_argument("--chart", type=Path, default=None, help="PNG to draw (default OUT/speed_accuracy.png)")
    sa.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    sa.set_defaults(handler=_speed_accuracy)

    st = benches.add_parser(
        "stability",
        help="per model: horizon sweep, failure faithfulness, counterfactuals, calibration/mount/robot-model errors, "
        "OOD actions, action shuffle",
    )
    st.add_argument("--quick", action="store_true", help="1 subtask per task × checkpoint, 1 probe start each")
    st.add_argument(
        "--models",
        default="",
        help="bench variants side by side, comma-separated (default: pilworld,v2_paper_gamma)",
    )
    st.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config (default: the simulated rig)")
    st.add_argument("--subtasks", type=int, default=None, help="20-round pairs per task × checkpoint (default 1 / 5)")
    st.add_argument("--starts", type=int, default=None, help="probe starts per task × checkpoint (default 1 / 4)")
    st.add_argument("--out", type=Path, default=None, help="run folders (default bench_runs/stability-quick|full)")
    st.add_argument("--workers", type=int, default=None, help="judging processes (default: one per CPU)")
    st.add_argument("--chart", type=Path, default=None, help="PNG to draw (default OUT/stability.png)")
    st.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    st.set_defaults(handler=_stability)

    jd = benches.add_parser("judges", help="image-only success judge vs the simulator's checker on a dataset")
    jd.add_argument("dataset", type=Path, help="a dataset with sim_checker verdicts (e.g. from pilworld sim collect)")
    jd.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config (default: the simulated rig)")
    jd.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    jd.set_defaults(handler=_judges)

    dr = benches.add_parser(
        "drivers", help="hardware drivers against the protocol fakes: servo rate, bus round trips, camera fps"
    )
    dr.add_argument(
        "--rig", type=Path, default=None, help="rig file with a hardware.fake section (default: the fake rig)"
    )
    dr.add_argument("--seconds", type=float, default=10.0, help="how long the robot is driven (default 10)")
    dr.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    dr.set_defaults(handler=_drivers)

    pp = benches.add_parser(
        "ppi",
        help="PPI++ intervals on the simulated rig: coverage, widths vs the variance formula, effective sample size",
    )
    pp.add_argument("--pool", type=Path, default=None, help="a judged paired run to draw from (default: run one)")
    pp.add_argument("--out", type=Path, default=Path("bench_runs/ppi"), help="where the pool is run (default)")
    pp.add_argument("--draws", type=int, default=None, help="draws per checkpoint and setting (default 2000)")
    pp.add_argument("--seed", type=int, default=0, help="sampling seed (default 0)")
    pp.add_argument("--quick", action="store_true", help="a 60-pair pool and 200 draws (≤ 5 minutes)")
    pp.add_argument("--json", action="store_true", help="print the whole result as JSON")
    pp.set_defaults(handler=_ppi)

    hl = benches.add_parser("hallucination", help="hallucination detector on injected faults and clean episodes")
    hl.add_argument("dataset", type=Path, help="a dataset of real-branch episodes (e.g. from pilworld sim collect)")
    hl.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config (default: the simulated rig)")
    hl.add_argument("--per-fault", type=int, default=None, help="faulted episodes per fault type (default: all)")
    hl.add_argument("--seed", type=int, default=0)
    hl.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    hl.set_defaults(handler=_hallucination)

    wp = benches.add_parser("world-model-presets", help="parameter counts and chunk latency of every native preset")
    wp.add_argument("--presets", default="", help="comma-separated presets (default: all)")
    wp.add_argument("--repeats", type=int, default=10, help="timed calls per preset; the median is reported")
    wp.add_argument("--steps", type=int, default=None, help="Euler steps (default: each preset's own)")
    wp.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    wp.set_defaults(handler=_world_model_presets)

    wm = benches.add_parser(
        "world-model",
        help="world model: single-step PSNR/SSIM on held-out sim episodes vs the frozen baseline, chunk latency",
    )
    wm.add_argument(
        "--checkpoint",
        type=Path,
        default=None,
        help="world-model checkpoint (default: v1, pilworld.world_model.V1_CHECKPOINT)",
    )
    wm.add_argument("--adapter", default=None, help="LoRA adapter of the checkpoint to apply (a task name)")
    wm.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config (default: the simulated rig)")
    wm.add_argument("--tasks", default="all", help="comma-separated tasks of the held-out runs (default all)")
    wm.add_argument("--episodes", type=int, default=2, help="held-out runs per task and checkpoint (default 2)")
    wm.add_argument("--seed0", type=int, default=None, help="first held-out seed (default 1000000; training used 0-19)")
    wm.add_argument("--clips", type=int, default=120, help="max held-out clips scored, a seeded subset (default 120)")
    wm.add_argument("--batch", type=int, default=1, help="clips per predict_batch call for the scores (default 1)")
    wm.add_argument("--steps", type=int, default=None, help="sampling steps (default: the model's)")
    wm.add_argument("--repeats", type=int, default=20, help="timed single-chunk calls for the latency (default 20)")
    wm.add_argument("--no-ablation", action="store_true", help="skip the no-history ablation figures")
    wm.add_argument("--lpips-weights", type=Path, default=None, help="folder holding the LPIPS AlexNet weights")
    wm.add_argument("--workers", type=int, default=None, help="processes collecting the held-out runs (default: CPUs)")
    wm.add_argument("--seed", type=int, default=0)
    wm.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    wm.set_defaults(handler=_world_model)

    cl = benches.add_parser(
        "chunk-latency", help="one imagined round (control video + prediction + state) per world model, round-robin"
    )
    cl.add_argument(
        "--models",
        default="",
        help="NAME=FOLDER,... (default: v1 = sim_small, v2 = the shipped sim_composite); ratios to the first",
    )
    cl.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config (default: the simulated rig)")
    cl.add_argument("--task", default="sort_cubes", help="task of the start and of the adapter (default sort_cubes)")
    cl.add_argument("--repeats", type=int, default=20, help="timed rounds per model; the median is reported")
    cl.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    cl.set_defaults(handler=_chunk_latency)

    wl = benches.add_parser(
        "wm-ladder",
        help="diagnostic ladder: state contract, autoencoded frames, judge fairness, teacher-forced vs free PSNR",
    )
    wl.add_argument("--quick", action="store_true", help="3 tasks × 3 checkpoints × 1 subtask (≤ 5 min on 2 cores)")
    wl.add_argument("--subtasks", type=int, default=None, help="subtasks per task × checkpoint (default 1 quick / 2)")
    wl.add_argument("--model", type=Path, default=None, help="world-model folder (default: v1, sim_small)")
    wl.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config (default: the simulated rig)")
    wl.add_argument("--rungs", default="", help="comma-separated rungs (default: all four)")
    wl.add_argument("--tasks", default="all", help="comma-separated tasks (default all three)")
    wl.add_argument("--checkpoints", default="", help="comma-separated scripted checkpoints (default: 3 quick / all 5)")
    wl.add_argument("--rounds", type=int, default=None, help="closed-loop rounds per subtask (default 5)")
    wl.add_argument("--out", type=Path, default=None, help="cache folder, resumed (default bench_runs/wm_ladder)")
    wl.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: torch's own)")
    wl.add_argument("--no-progress", action="store_true", help="no progress bars on stderr")
    wl.add_argument("--json", action="store_true", help="print the result as one JSON object on the last line")
    wl.set_defaults(handler=_wm_ladder)


def _control_video(args: argparse.Namespace) -> int:
    from pilworld.bench.control_video import run_control_video_bench

    spec = ChunkSpec(horizon=max(50, args.frames * args.stride), frames=args.frames, stride=args.stride)
    style = Style.parse(args.style)
    if style.name != "markers":
        return _gamma_plus(args, style, spec)
    result = run_control_video_bench(
        args.rig,
        chunks=args.chunks,
        batch=args.batch,
        size=parse_size(args.size or "128x128"),
        spec=spec,
        repeats=args.repeats,
        seed=args.seed,
        progress=not args.json,
    )
    print(
        f"control-video: {result['frames_per_s']:.0f} frames/s ({result['image_size'][0]}x{result['image_size'][1]}, "
        f"K={result['K']}), {result['ms_per_chunk_single_p50']:.3f} ms per single chunk"
    )
    return emit(args, result)


def _gamma_plus(args: argparse.Namespace, style: Style, spec: ChunkSpec) -> int:
    from pilworld.bench.gamma_plus import SHIPPED_MODEL, run_gamma_plus_bench

    model: Path | None = SHIPPED_MODEL if args.world_model is None else args.world_model
    if model is not None and str(model).lower() == "none":
        model = None
    result = run_gamma_plus_bench(
        args.rig,
        style.name,
        backend=args.backend,
        starts=args.starts,
        chunks_per_start=args.chunks_per_start,
        repeats=args.repeats,
        world_model=model,
        size=parse_size(args.size) if args.size else None,
        spec=spec,
        seed=args.seed,
        progress=not args.json,
    )
    line = (
        f"control-video {result['style']}: {result['ms_per_chunk_p50']:.1f} ms per chunk "
        f"(K={result['K']} × {len(result['views'])} views at {result['image_size'][0]}x{result['image_size'][1]})"
    )
    if "world_model" in result:
        line += (
            f"; world model {result['world_model']['chunk_latency_ms']:.1f} ms per chunk in the same run "
            f"(ratio {result['ratio_to_world_model']:.2f})"
        )
    print(line)
    return emit(args, result)


def _robot_render(args: argparse.Namespace) -> int:
    from pilworld.bench.robot_render import run_robot_render_accuracy

    result = run_robot_render_accuracy(
        args.rig,
        configs_per_arm=args.configs_per_arm,
        seed=args.seed,
        backend=args.backend,
        task=args.task,
        out=args.out,
    )
    for view, r in result["views"].items():
        print(f"{view:16s} mean IoU {r['mean_iou']:.4f}  worst {r['worst_iou']:.4f} (config {r['worst_config']})")
    return emit(args, result)


def _reprojection(args: argparse.Namespace) -> int:
    from pilworld.bench.reprojection import run

    return run(args)


def _data(args: argparse.Namespace) -> int:
    from pilworld.bench.data import run_data_bench

    result = run_data_bench(
        episodes=args.episodes, length=args.length, size=args.size, video_mode=args.video_mode, progress=not args.json
    )
    print(
        f"data ({result['video_mode']}, 3 views at {args.size}x{args.size}): write {result['write_frames_per_s']:.0f} "
        f"frames/s, read {result['read_frames_per_s']:.0f} frames/s, clips {result['clips_per_s']:.0f}/s "
        f"({result['clips_per_s_cold']:.0f}/s while decoding)"
    )
    return emit(args, result)


def _sim(args: argparse.Namespace) -> int:
    from pilworld.bench.sim import run_sim_bench
    from pilworld.collection.tasks import require_simulated, resolve_tasks
    from pilworld.options.bounds import SIM_REPEATS, TRY_SUBTASKS, WORKERS, check_count
    from pilworld.policies.scripted import CHECKPOINTS

    check_count(args.subtasks, "--subtasks", TRY_SUBTASKS)
    check_count(args.workers, "--workers", WORKERS)
    check_count(args.repeats, "--repeats", SIM_REPEATS)
    (task,) = resolve_tasks([args.task], what="--task")
    tasks = resolve_tasks(args.tasks, what="--tasks")
    require_simulated([task], what="--task")
    require_simulated(tasks, what="--tasks")
    ckpts = _names(args.checkpoints, [c.name for c in CHECKPOINTS], "--checkpoints")
    result = run_sim_bench(
        str(args.rig),
        task=task,
        subtasks=args.subtasks or 0,
        tasks=list(tasks),
        appearance=args.appearance,
        checkpoints=ckpts,
        workers=args.workers,
        progress=not args.json,
        repeats=args.repeats,
        baseline=args.baseline,
    )
    print(
        f"sim ({args.appearance}): {result['physics_steps_per_s']:.0f} physics steps/s, "
        f"{result['render_ms_per_view']:.1f} ms per view, realtime factor {result['realtime_factor']:.1f}"
    )
    if "baseline" in result:
        b, r = result["baseline"], result["baseline_ratio"]
        print(
            f"  {b['appearance']}: {b['render_ms_per_view']:.1f} ms per view, realtime factor "
            f"{b['realtime_factor']:.1f}; {args.appearance} / {b['appearance']}: "
            f"render ×{r['render_ms_per_view']:.2f}, "
            f"realtime ×{r['realtime_factor']:.2f} (median of {args.repeats}, measured side by side)"
        )
    for task, rates in result.get("success_rates", {}).items():
        print(f"  {task}: " + ", ".join(f"{c} {r:.2f}" for c, r in rates.items()))
    return emit(args, result)


def _calibration(args: argparse.Namespace) -> int:
    from pilworld.bench.calibration import run_calibration_bench

    r = run_calibration_bench(
        seeds=args.seeds,
        views=args.views,
        trials=args.trials,
        quick=args.quick,
        out_dir=args.out,
        handeye_source=args.handeye_source,
        handeye_poses=args.handeye_poses,
        rig_path=args.rig,
        seed=args.seed,
        progress=not args.no_progress,
    )
    print(
        f"intrinsics ({r['intrinsics_seeds']} seeds x {r['intrinsics_views']} views, {r['intrinsics_noise_px']} px): "
        f"|Δf|/f {r['intrinsics_focal_rel_err_percent']:.3f} %, principal point {r['intrinsics_pp_err_px']:.2f} px, "
        f"RMS {r['intrinsics_rms_px']:.3f} px (max {r['intrinsics_rms_px_max']:.3f}), 95 % intervals cover "
        f">= {r['intrinsics_ci95_coverage']:.0%} of seeds"
    )
    print(
        f"hand-eye ({r['handeye_source']}): {r['handeye_trans_err_mm']:.3g} mm, {r['handeye_rot_err_deg']:.3g}°, "
        f"gripper reprojection {r['gripper_reproj_err_px']:.3g} px"
    )
    syn = r["handeye_synthetic"]
    if r["handeye_source"] != "synthetic":
        print(
            f"hand-eye (synthetic, {syn['pixel_noise_px']} px noise, {syn['poses']} poses): "
            f"{syn['handeye_trans_err_mm']:.3g} mm, {syn['handeye_rot_err_deg']:.3g}°"
        )
    if "wrist" in r:
        for cam, w in r["wrist"]["cameras"].items():
            print(
                f"eye-in-hand {cam} ({r['wrist_source']}): max {w['trans_err_mm_max']:.3g} mm, "
                f"{w['rot_err_deg_max']:.3g}° over the seeds (median {w['trans_err_mm_median']:.3g} mm, "
                f"{w['rot_err_deg_median']:.3g}°)"
            )
    settings = r["sweep_settings"]
    print(f"sweep: {settings['trials']} trials per point, OpenCV {r['opencv_version']} (median mm / median deg)")
    for axis, per in r["sweep"].items():
        print(f"  {axis}:")
        for method, stats in per.items():
            cells = [
                f"{s['value']:g}: "
                + (
                    "refused"
                    if s["trans_mm_median"] is None
                    else f"{s['trans_mm_median']:.2f}/{s['rot_deg_median']:.2f}"
                )
                for s in stats
            ]
            print(f"    {method:<18} " + "  ".join(cells))
    print(f"chart: {r['chart']}")
    return emit(args, r)


def _chunk_latency(args: argparse.Namespace) -> int:
    from pilworld.bench.chunk_latency import parse_models, run_chunk_latency
    from pilworld.world_model import DEFAULT_CHECKPOINT, V1_CHECKPOINT

    text = args.models or f"v1={V1_CHECKPOINT},v2={DEFAULT_CHECKPOINT}"
    result = run_chunk_latency(parse_models(text), rig=args.rig, task=args.task, repeats=args.repeats)
    for name, m in result["models"].items():
        print(f"{name:>12}: median {m['median_ms']:.1f} ms, p90 {m['p90_ms']:.1f} ms, ×{m['ratio_to_first']:.2f}")
    return emit(args, result)


def _world_model_presets(args: argparse.Namespace) -> int:
    from pilworld.bench.world_model_presets import run_presets_bench

    names = [n for n in args.presets.split(",") if n] or None
    result = run_presets_bench(names, repeats=args.repeats, steps=args.steps, progress=not args.json)
    for name, r in result["presets"].items():
        w, h = r["image_size"]
        print(
            f"{name:>6}: {r['params'] / 1e6:6.2f} M params ({r['float32_mb']} MB float32), {w}x{h}, "
            f"{r['steps']} steps: {r['chunk_latency_ms']:.1f} ms per chunk, realtime x{r['realtime_factor']}"
        )
    return emit(args, result)


def _world_model(args: argparse.Namespace) -> int:
    # Imported here: the checkpoint loader pulls in torch and the model code, which other commands do not need.
    import pilworld.world_model as world_model
    from pilworld.bench.world_model import HELDOUT_SEED0, heldout_dataset, run_world_model_bench
    from pilworld.world_model.checkpoint import load_world_model
    from simrig.tasks import TASK_NAMES

    # v1 by default: the bench's presets, steps and open-loop figures (docs/world_model.md) are v1's.
    checkpoint = args.checkpoint or getattr(world_model, "V1_CHECKPOINT", None)
    if checkpoint is None:
        raise ValueError("--checkpoint: required (pilworld.world_model defines no V1_CHECKPOINT)")
    if not Path(checkpoint).exists():
        raise FileNotFoundError(f"--checkpoint: {checkpoint} not found")
    tasks = _names(args.tasks, list(TASK_NAMES), "--tasks")
    model = load_world_model(Path(checkpoint), adapter=args.adapter)
    no_history = None
    if not args.no_ablation and hasattr(model, "without_history"):
        no_history = model.without_history()
    root = heldout_dataset(
        args.rig,
        tasks=tasks,
        episodes=args.episodes,
        seed0=HELDOUT_SEED0 if args.seed0 is None else args.seed0,
        workers=args.workers,
        progress=not args.json,
    )
    result = run_world_model_bench(
        model,
        heldout=root,
        no_history=no_history,
        steps=args.steps,
        clips=args.clips,
        batch=args.batch,
        repeats=args.repeats,
        seed=args.seed,
        rig=args.rig,
        progress=not args.json,
        lpips_weights=args.lpips_weights,
    )
    result = {"checkpoint": str(checkpoint), "adapter": args.adapter, **result}
    w, h = result["image_size"]
    print(
        f"world-model ({result['model']}, {w}x{h}, K={result['K']}): {result['clips']} held-out clips, "
        f"PSNR {result['psnr']:.2f} dB (frozen {result['psnr_frozen']:.2f}), "
        f"SSIM {result['ssim']:.3f} (frozen {result['ssim_frozen']:.3f})"
    )
    nh = result["no_history"]
    rows = [
        {
            "view": view,
            "psnr": fig["psnr"],
            "frozen": result["per_view_frozen"][view]["psnr"],
            "gain": result["gain_over_frozen_db"][view],
            "pooled": result["gain_over_frozen_pooled_db"][view],
            "no_history": nh["per_view"][view]["psnr"] if nh else None,
        }
        for view, fig in result["per_view"].items()
    ]
    for line in table(WORLD_MODEL_COLUMNS if nh else WORLD_MODEL_COLUMNS[:-1], rows):
        print(line)
    exact = {v: f["exact"] for v, f in result["per_view_frozen"].items() if f["exact"] > 0}
    if exact:  # these frames score the 100 dB cap and lift psnr_frozen
        shares = ", ".join(f"{v} {x:.0%}" for v, x in exact.items())
        print(f"  frozen baseline bit-exact (static view, PSNR capped at 100 dB): {shares}")
    if "lpips" in result:
        print(f"  LPIPS {result['lpips']:.4f} (frozen {result['lpips_frozen']:.4f})")
    else:
        print(f"  LPIPS not computed: {result['lpips_absent_reason']}")
    print(
        f"  latency {result['chunk_latency_ms']:.1f} ms per chunk (p90 {result['chunk_latency_ms_p90']:.1f}, "
        f"steps {result['steps'] if result['steps'] is not None else 'default'}, {result['torch_threads']} threads), "
        f"realtime factor {result['realtime_factor']:.2f}"
    )
    return emit(args, result)


def _wm_ladder(args: argparse.Namespace) -> int:
    from pilworld.bench.wm_ladder import DEFAULT_OUT, RUNGS, TASKS, LadderConfig, run_wm_ladder, summary_lines

    if args.subtasks is not None and args.subtasks < 1:
        raise ValueError(f"--subtasks: expected at least 1, got {args.subtasks}")
    if args.threads is not None:
        if args.threads < 1:
            raise ValueError(f"--threads: expected at least 1, got {args.threads}")
        import torch

        torch.set_num_threads(args.threads)
    if args.rounds is not None and args.rounds < 1:
        raise ValueError(f"--rounds: expected at least 1, got {args.rounds}")

    def names(value: str) -> tuple[str, ...]:
        return tuple(v.strip() for v in value.split(",") if v.strip())

    cfg = LadderConfig(
        model=str(args.model) if args.model is not None else "",
        rig=str(args.rig),
        quick=args.quick,
        subtasks=args.subtasks,
        tasks=TASKS if args.tasks.strip() == "all" else names(args.tasks),
        checkpoints=names(args.checkpoints) or None,
        rungs=names(args.rungs) or RUNGS,
        spec=ChunkSpec() if args.rounds is None else ChunkSpec(rounds=args.rounds),
        out=str(args.out or DEFAULT_OUT),
    )
    r = run_wm_ladder(cfg, progress=not args.no_progress)
    for line in summary_lines(r):
        print(line)
    return emit(args, r)


def _paired_timing(args: argparse.Namespace) -> int:
    from pilworld.bench.paired_timing import bench_paired

    for name in ("subtasks", "rounds"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name}: expected at least 1, got {getattr(args, name)}")
    r = bench_paired(
        rig=str(args.rig),
        task=args.task,
        checkpoint=args.checkpoint,
        subtasks=args.subtasks,
        rounds=args.rounds,
        world_model=args.world_model,
        progress=not args.json,
    )
    for origin in ("real", "imagined"):
        b = r[origin]
        print(
            f"paired {origin}: {b['seconds_per_subtask']['median']} s per subtask (median of {r['subtasks']}), "
            f"policy {b['policy_ms_per_round']['median']} ms and env {b['env_ms_per_round']['median']} ms per round, "
            f"realtime x{b['realtime_factor']}"
        )
    return emit(args, r)


def _paired(args: argparse.Namespace) -> int:
    from pilworld.bench.charts import paired_table_chart
    from pilworld.bench.paired import run_paired_bench

    if args.subtasks is not None and args.subtasks < 1:
        raise ValueError(f"--subtasks: expected at least 1, got {args.subtasks}")
    out = args.out or Path("bench_runs") / ("paired-quick" if args.quick else "paired-full")
    names = [n.strip() for n in args.variants.split(",") if n.strip()] or None
    r = run_paired_bench(
        out=out,
        rig=args.rig,
        quick=args.quick,
        variants=names,
        subtasks=args.subtasks,
        seed=args.seed,
        workers=args.workers,
        progress=not args.json,
        real_from=args.real_from,
    )
    chart = paired_table_chart(r["variants"], r["targets"], args.chart or Path(out) / "paired.png")
    r["chart"] = str(chart)
    p = r["protocol"]
    print(
        f"paired ({'quick' if r['quick'] else 'full'}): {len(p['tasks'])} tasks × {len(p['checkpoints'])} checkpoints "
        f"× {p['subtasks']} subtasks, R={p['rounds']}, seeds from {p['seed0']}"
    )
    rows = [
        {"variant": name, **row["overall"], "head": (row["single_step"]["per_view"] or {}).get("cam_high", {})}
        for name, row in r["variants"].items()
    ]
    for line in table(PAIRED_COLUMNS, rows):
        print(line)
    print(f"  targets: |ΔSR| ≤ 5 points, HFR ≥ 0.85, Pearson ≥ 0.95; chart {chart}")
    return emit(args, r)


def _speed_accuracy(args: argparse.Namespace) -> int:
    from pilworld.bench.charts import speed_accuracy_chart
    from pilworld.bench.speed_accuracy import run_speed_accuracy

    try:
        steps = [int(s) for s in args.steps.split(",") if s.strip()] or None
    except ValueError:
        raise ValueError(f"--steps: expected comma-separated integers such as 1,2,4, got {args.steps!r}") from None
    if steps and min(steps) < 1:
        raise ValueError(f"--steps: expected integers >= 1, got {args.steps!r}")
    for name in ("clips", "repeats", "subtasks"):
        if getattr(args, name) is not None and getattr(args, name) < 1:
            raise ValueError(f"--{name}: expected at least 1, got {getattr(args, name)}")
    out = args.out or Path("bench_runs") / ("speed-accuracy-quick" if args.quick else "speed-accuracy-full")
    r = run_speed_accuracy(
        rig=args.rig,
        quick=args.quick,
        steps=steps,
        clips=args.clips,
        repeats=args.repeats,
        subtasks=args.subtasks,
        out=out,
        workers=args.workers,
        progress=not args.json,
    )
    d, shipped = r["default"], r["shipped_default"]
    chart = speed_accuracy_chart(
        r["points"], r["front_ids"], args.chart or out / "speed_accuracy.png", knee=d.get("id"), shipped=shipped["id"]
    )
    r["chart"] = str(chart)
    loop = r["closed_loop"]
    pairs = f"{loop['pairs_per_point']} closed-loop pairs per point" if "pairs_per_point" in loop else loop["skipped"]
    print(f"speed-accuracy ({'quick' if r['quick'] else 'full'}): {len(r['points'])} points, {pairs}, chart {chart}")
    print(f"  latency: {r['latency']['measures']}")
    rows = [
        {
            **p,
            "front": "*" if p["id"] in r["front_ids"] else "",
            "remark": p.get("skipped") or p.get("untrained") or p.get("closed_loop") or "",
        }
        for p in r["points"]
    ]
    for line in table(SPEED_ACCURACY_COLUMNS, rows):
        print(line)
    if d.get("id") is None:
        print(f"  knee: none ({d['none']})")
    else:
        print(
            f"  knee: {d['id']} ({d['family']}{'' if d['preset'] == d['family'] else ' ' + d['preset']} "
            f"{d['size']}, {d['params']:,} parameters), "
            f"{d['chunk_latency_ms']:.1f} ms per round, |ΔSR| {pct(d['abs_delta_sr'])}, HFR {num(d['hfr'], 3)} "
            f"— {d['rule']}"
        )
        print(f"  shipped default ({shipped['id']}): {shipped['verdict']}")
    single = r["single_step_knee"]
    print(f"  single-step knee (head PSNR, for contrast): {single.get('id') or single.get('none')}")
    return emit(args, r)


def _stability(args: argparse.Namespace) -> int:
    from pilworld.bench.charts import stability_chart
    from pilworld.bench.stability import run_stability

    for name in ("subtasks", "starts"):
        if getattr(args, name) is not None and getattr(args, name) < 1:
            raise ValueError(f"--{name}: expected at least 1, got {getattr(args, name)}")
    out = args.out or Path("bench_runs") / ("stability-quick" if args.quick else "stability-full")
    models = [n.strip() for n in args.models.split(",") if n.strip()] or None
    r = run_stability(
        rig=args.rig,
        quick=args.quick,
        out=out,
        subtasks=args.subtasks,
        starts=args.starts,
        workers=args.workers,
        models=models,
        progress=not args.json,
    )
    chart = stability_chart(r, args.chart or out / "stability.png")
    r["chart"] = str(chart)
    p = r["probe_protocol"]
    print(
        f"stability ({'quick' if r['quick'] else 'full'}): {len(r['models'])} model(s), {p['starts']} probe starts, "
        f"{len(r['refused'])} probe chunk(s) refused, {r['wall_s']} s; chart {chart}"
    )
    for name, m in r["models"].items():
        print(f"[{name}] {m['label']}")
        rows = m["horizon"]["rows"]
        print("  horizon R " + "".join(f"{row['rounds']:>7}" for row in rows))
        print("  HFR       " + "".join(f"{num(row['hfr'], 3):>7}" for row in rows))
        f = m["failure_faithfulness"]
        print(
            f"  failure faithfulness: {pct(f['imagined_also_failed'])} % of {f['real_failures']} real failures also "
            f"failed imagined; {pct(f['imagined_also_succeeded'])} % of {f['real_successes']} successes succeeded"
        )
        print(
            "  counterfactual, head MSE ratio model/sim: "
            + ", ".join(
                f"vs {row['alternative']} {num(row['cam_high']['ratio_median'])}" for row in m["counterfactual"]["rows"]
            )
        )
        errors = m["calibration"]["rows"] + m["robot_mismatch"]["rows"]
        print(f"  head PSNR {num(errors[0]['psnr_head'])} dB on the right rig; change with a wrong one, dB:")
        for row in errors[1:]:
            if row["applies"]:
                print(
                    f"    {row['label']}: {num(row['delta_db'])} ("
                    + ", ".join(f"{v} {num(d)}" for v, d in row["delta_per_view"].items())
                    + ")"
                )
            else:
                print(f"    {row['label']}: does not reach this model")
        print(
            "  OOD actions → head PSNR: "
            + ", ".join(f"{row['kind']} {num(row['psnr_head'])}" for row in m["ood_actions"]["rows"])
        )
        sh = m["action_shuffle"]
        head = sh["per_view"].get("cam_high") or {}
        print(
            f"  action shuffle ({sh['rounds']} rounds, {sh['n']} starts), head view: MSE ratio model/sim "
            f"{num(head.get('ratio_median'))}, futures differ in {pct(head.get('distinct_share'))} %; PSNR shuffled "
            f"{num(head.get('psnr_shuffled'))} vs own {num(head.get('psnr_own'))} dB; deterministic "
            f"{pct(sh['deterministic_share'])} %"
        )
    return emit(args, r)


def _judges(args: argparse.Namespace) -> int:
    from pilworld.bench.judges import run_judge_bench
    from pilworld.config.rig import RigConfig

    r = run_judge_bench(args.dataset, RigConfig.load(args.rig), progress=not args.json)
    print(f"judges: image-only judge agrees with the checker on {r['agreement']} of {r['n']} real episodes")
    for task, t in r["per_task"].items():
        print(f"  {task}: {t['agreement']} of {t['n']}, confusion {t['confusion']}")
    return emit(args, r)


def _drivers(args: argparse.Namespace) -> int:
    from pilworld.bench.drivers import FAKE_RIG, run_drivers_bench

    r = run_drivers_bench(args.rig or FAKE_RIG, args.seconds, progress=not args.json)
    print(
        f"drivers: servo {r['servo_rate_hz']} Hz (target {r['servo_rate_target_hz']}), p99 period "
        f"{r['servo_period_p99_ms']} ms; round trips: dynamixel {r['dynamixel_roundtrip_ms']} ms, "
        f"robotiq {r['robotiq_roundtrip_ms']} ms; cameras {r['camera_fps']} fps (served {r['camera_fps_served']})"
        f"; calls (p99): gripper set_target {r['gripper_set_target_p99_ms']} ms, "
        f"camera read_latest {r['camera_read_latest_p99_ms']} ms"
    )
    return emit(args, r)


def _ppi(args: argparse.Namespace) -> int:
    from pilworld.bench.ppi import run_ppi_bench

    if args.draws is not None and args.draws < 1:
        raise ValueError(f"--draws: expected at least 1, got {args.draws}")
    r = run_ppi_bench(
        pool=args.pool, out=args.out, quick=args.quick, draws=args.draws, seed=args.seed, progress=not args.json
    )
    lines = [f"pool {r['pool']}: real success rate per checkpoint {r['pool_truth']}, per-pair rho {r['pool_rho']}"]
    lines += table(PPI_COLUMNS, r["settings"], indent="")
    lines.append("checks: " + json.dumps(r["checks"]))
    return emit(args, r, lines)


def _hallucination(args: argparse.Namespace) -> int:
    from pilworld.bench.hallucination import run_hallucination_bench

    r = run_hallucination_bench(
        args.dataset, args.rig, seed=args.seed, per_fault=args.per_fault, progress=not args.json
    )
    summary = {k: v for k, v in r.items() if not isinstance(v, (list, dict))}
    return emit(args, r, [", ".join(f"{k} {v}" for k, v in summary.items())])
