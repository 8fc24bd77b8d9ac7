"""``pilworld train pretrain|finetune``: the world model's two training stages (see
:mod:`pilworld.world_model.training.trainer`). ``--nproc N`` re-launches the same command under
``torchrun`` with N processes (DDP; gloo on CPU, nccl on GPUs)."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

from pilworld.options.parse import parse_size
from simrig.files import SIM_RIG, SIM_RIG_IN_CHECKOUT


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", type=Path, required=True, help="training dataset folder (LeRobot v3.0 layout)")
    p.add_argument("--out", type=Path, required=True, help="run folder (created, or resumed when it exists)")
    p.add_argument("--rig", type=Path, default=SIM_RIG, help="rig config for the control video (default: sim)")
    p.add_argument("--steps", type=int, default=4000, help="Ψ_θ (or LoRA) optimiser steps (default 4000)")
    p.add_argument("--batch", type=int, default=16, help="clips per step, over all processes (default 16)")
    p.add_argument("--lr", type=float, default=None, help="learning rate (default 3e-4; LoRA 1e-3)")
    p.add_argument("--window", type=int, default=9, help="clip window W in stride-sampled frames (default 9)")
    p.add_argument(
        "--success-fraction",
        type=float,
        default=None,
        help="share of clips from successes (default: as stored; 1 = success-only)",
    )
    p.add_argument("--checkpoint-every", type=int, default=250, help="steps between checkpoints (default 250)")
    p.add_argument("--validate-every", type=int, default=500, help="steps between validations (default 500)")
    p.add_argument("--val-clips", type=int, default=24, help="validation clips (default 24)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--nproc", type=int, default=1, help="processes; >1 re-launches under torchrun (default 1)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser("train", help="train the world model (stage 1 or stage 2)")
    stages = p.add_subparsers(dest="stage", metavar="STAGE")
    stages.required = True

    pre = stages.add_parser("pretrain", help="stage 1: the frame VAE, then Ψ_θ, on all tasks")
    _common(pre)
    pre.add_argument("--preset", default="small", help="model preset: tiny, small (default), base")
    pre.add_argument("--size", default=None, help="WIDTHxHEIGHT replacing the preset's image size (e.g. 64x64)")
    pre.add_argument("--tasks", default="", help="comma-separated tasks (default: all in the dataset)")
    pre.add_argument("--vae-steps", type=int, default=2000, help="frame-VAE steps before Ψ_θ (default 2000)")
    pre.add_argument("--vae-batch", type=int, default=32, help="frames per VAE step (default 32)")
    pre.add_argument("--no-history", action="store_true", help="ablation: no latent history memory")
    pre.add_argument("--action-tokens", action="store_true", help="ablation: add per-frame raw-action tokens")
    pre.add_argument(
        "--no-control-video", action="store_true", help="ablation: no control video (needs --action-tokens)"
    )
    pre.set_defaults(handler=_run)

    fin = stages.add_parser("finetune", help="stage 2: LoRA on one target task, success and failure clips")
    _common(fin)
    fin.add_argument("--init", type=Path, required=True, help="stage-1 model folder (RUN/model)")
    fin.add_argument("--task", required=True, help="the target task")
    fin.add_argument("--lora-rank", type=int, default=16, help="LoRA rank (default 16)")
    fin.set_defaults(handler=_run)

    exp = stages.add_parser("export", help="a shippable model folder: weights in float16 plus stage-2 adapters")
    exp.add_argument("source", type=Path, help="stage-1 model folder (RUN/model)")
    exp.add_argument("--adapters", type=Path, nargs="*", default=[], help="stage-2 model folders whose adapters to add")
    exp.add_argument("--dtype", default="float16", choices=["float16", "bfloat16", "float32"])
    exp.add_argument("--steps", type=int, default=None, help="default sampling steps of the exported model")
    exp.add_argument("--out", type=Path, required=True, help="destination folder")
    exp.set_defaults(handler=_export)

    comp = stages.add_parser(
        "composite", help="world model v2: the compositing U-Net over Γ⁺ layers (resumable: rerun to continue)"
    )
    comp.add_argument("--data", type=Path, required=True, help="training dataset (pilworld sim collect)")
    comp.add_argument("--out", type=Path, required=True, help="run folder (created or resumed)")
    comp.add_argument("--rig", default=SIM_RIG_IN_CHECKOUT, help="rig config whose geometry it composites")
    comp.add_argument("--steps", type=int, default=4000, help="optimiser steps (default 4000; may grow on resume)")
    comp.add_argument("--batch", type=int, default=32, help="samples (view × frame) per step (default 32)")
    comp.add_argument("--lr", type=float, default=2e-3, help="peak learning rate (default 2e-3)")
    comp.add_argument("--width", type=int, default=16, help="U-Net base width (default 16)")
    comp.add_argument("--work-size", type=int, default=32, help="U-Net resolution (default 32)")
    comp.add_argument("--cache-size", type=int, default=64, help="training composite resolution (default 64)")
    comp.add_argument("--max-clips", type=int, default=3000, help="clips in the sample cache (default 3000)")
    comp.add_argument("--seed", type=int, default=0)
    comp.add_argument("--checkpoint-every", type=int, default=250)
    comp.add_argument("--validate-every", type=int, default=500)
    comp.add_argument("--threads", type=int, default=None, help="torch threads (default: torch's)")
    comp.add_argument(
        "--stop-after", type=int, default=None, help="checkpoint and exit after this many steps (rerun to continue)"
    )
    comp.add_argument(
        "--cache", type=Path, default=None, help="sample cache folder (default RUN/cache; variants can share one)"
    )
    comp.add_argument(
        "--cache-only", action="store_true", help="build the sample cache (with the variants' inputs) and exit"
    )
    var = comp.add_argument_group("variants of the recipe (docs/world_model.md, 'Variants')")
    var.add_argument(
        "--control",
        default="render+prior",
        help="control video: render+prior (shipped), render, markers (the paper's Γ) or none",
    )
    var.add_argument("--no-paste", action="store_true", help="leave the robot's pixels to the gates (not pasted)")
    var.add_argument("--no-history", action="store_true", help="hide the head view's memory layer")
    var.add_argument("--no-hands", action="store_true", help="let the gates decide at every pixel (no hand region)")
    var.add_argument("--action-tokens", action="store_true", help="the frame's commanded action as input planes")
    var.add_argument("--success-only", action="store_true", help="train on clips of successful episodes only")
    comp.set_defaults(handler=_composite)

    plot = stages.add_parser("plot", help="the training curve of a run folder as a PNG")
    plot.add_argument("run", type=Path, help="run folder (holds log.jsonl)")
    plot.add_argument("--out", type=Path, required=True, help="PNG file to write")
    plot.add_argument("--title", default=None)
    plot.set_defaults(handler=_plot)


def _composite(args: argparse.Namespace) -> int:
    from pilworld.world_model.composite.switches import Switches
    from pilworld.world_model.composite.train import TrainSettings, train_composite

    for name in (
        "steps",
        "batch",
        "width",
        "work_size",
        "cache_size",
        "max_clips",
        "checkpoint_every",
        "validate_every",
    ):
        if not 1 <= getattr(args, name) <= 10_000_000:
            raise ValueError(
                f"--{name.replace('_', '-')}: expected an integer in 1..10,000,000, got {getattr(args, name)}"
            )
    from pilworld.data.reader import EpisodeStore
    from pilworld.io.run_folder import TRAINING, check_out_folder

    check_out_folder(args.out, TRAINING)  # a folder another command made is refused before anything
    if not (args.data / "meta" / "info.json").is_file():
        raise ValueError(
            f"--data: {args.data} is not a dataset (no meta/info.json); record one with pilworld sim collect"
        )
    _ = EpisodeStore(args.data).episodes  # a damaged --data fails before --out is created
    settings = TrainSettings(
        data=str(args.data),
        rig=str(args.rig),
        steps=args.steps,
        batch=args.batch,
        lr=args.lr,
        width=args.width,
        work_size=args.work_size,
        cache_size=args.cache_size,
        seed=args.seed,
        max_clips=args.max_clips,
        switches=Switches(
            control=args.control,
            paste=not args.no_paste and args.control.startswith("render"),
            history=not args.no_history,
            hands=not args.no_hands,
            action_tokens=args.action_tokens,
        ),
        success_only=args.success_only,
    )
    out = train_composite(
        settings,
        args.out,
        checkpoint_every=args.checkpoint_every,
        validate_every=args.validate_every,
        threads=args.threads,
        stop_after=args.stop_after,
        cache_dir=args.cache,
        cache_only=args.cache_only,
    )
    if args.cache_only:
        print(f"sample cache ready in {args.cache or args.out / 'cache'}")
    else:
        print(f"wrote {out}" if out is not None else f"stopped after step {args.stop_after}; rerun to continue")
    return 0


def _plot(args: argparse.Namespace) -> int:
    from pilworld.world_model.training.curves import plot_training_curve

    print(f"wrote {plot_training_curve(args.run, args.out, args.title)}")
    return 0


def _export(args: argparse.Namespace) -> int:
    from pilworld.world_model.latent.checkpoint import adapter_names, export_model

    dest = export_model(
        args.source, args.out, adapters=list(args.adapters), dtype=torch_dtype(args.dtype), steps=args.steps
    )
    size = sum(f.stat().st_size for f in dest.rglob("*") if f.is_file())
    print(f"exported {dest} ({size / 1e6:.1f} MB; adapters: {adapter_names(dest) or 'none'})")
    return 0


def torch_dtype(name: str) -> Any:
    import torch

    return {"float16": torch.float16, "bfloat16": torch.bfloat16, "float32": torch.float32}[name]


def _relaunch(args: argparse.Namespace) -> int:
    if args.nproc < 1:
        raise ValueError(f"--nproc: expected >= 1, got {args.nproc}")
    # The command goes through unchanged: under torchrun WORLD_SIZE is set, so the ranks do not relaunch
    # again. (Cutting out "--nproc N" by position failed on the "--nproc=N" spelling.)
    argv = list(getattr(args, "argv", None) or sys.argv[1:])  # main(argv) records the real command line
    cmd = [
        sys.executable,
        "-m",
        "torch.distributed.run",
        "--standalone",
        f"--nproc_per_node={args.nproc}",
        "-m",
        "pilworld",
        *argv,
    ]
    env = dict(os.environ, OMP_NUM_THREADS=os.environ.get("OMP_NUM_THREADS", "1"))
    return subprocess.call(cmd, env=env)


def _run(args: argparse.Namespace) -> int:
    from pilworld.io.run_folder import TRAINING, check_out_folder
    from pilworld.world_model.training.trainer import TrainConfig, Trainer

    for name in ("steps", "batch", "window", "checkpoint_every", "validate_every", "val_clips"):
        value = getattr(args, name, None)
        if value is not None and not 1 <= value <= 10_000_000:
            raise ValueError(f"--{name.replace('_', '-')}: expected an integer in 1..10,000,000, got {value}")
    if not 1 <= args.nproc <= 64:
        raise ValueError(f"--nproc: expected an integer in 1..64 (processes on this machine), got {args.nproc}")
    if args.nproc != 1 and "WORLD_SIZE" not in os.environ:
        return _relaunch(args)  # (each rank checks --out and --data below)
    check_out_folder(args.out, TRAINING)  # a folder another command made is refused before anything
    from pilworld.data.reader import EpisodeStore

    _ = EpisodeStore(args.data).episodes  # a missing or damaged --data fails before --out is created
    finetune = args.stage == "finetune"
    cfg = TrainConfig(
        stage=args.stage,
        data=str(args.data),
        out=str(args.out),
        rig=str(args.rig),
        preset="" if finetune else args.preset,
        size=None if finetune or args.size is None else parse_size(args.size),
        init=str(args.init) if finetune else None,
        tasks=(args.task,) if finetune else tuple(t for t in args.tasks.split(",") if t),
        success_fraction=args.success_fraction,
        window=args.window,
        history=not getattr(args, "no_history", False),
        control_video=not getattr(args, "no_control_video", False),
        action_tokens=getattr(args, "action_tokens", False),
        vae_steps=0 if finetune else args.vae_steps,
        vae_batch=getattr(args, "vae_batch", 32),
        steps=args.steps,
        batch=args.batch,
        lr=args.lr if args.lr is not None else (1e-3 if finetune else 3e-4),
        lora_rank=getattr(args, "lora_rank", 16),
        checkpoint_every=args.checkpoint_every,
        validate_every=args.validate_every,
        val_clips=args.val_clips,
        seed=args.seed,
    )
    final = Trainer(cfg, progress=not args.quiet).run()
    if int(os.environ.get("RANK", "0")) == 0:
        print(f"model: {final}")
    return 0
