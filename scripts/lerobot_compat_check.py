#!/usr/bin/env python
"""Load a LeRobot v3.0 dataset with LeRobot's own ``LeRobotDataset`` (offline) and summarise it.

Standalone: run it with the interpreter of the LeRobot virtualenv made by
``scripts/setup_lerobot_venv.sh`` (default .venv-lerobot), never with the project's
interpreter; it does not import pilworld.

    .venv-lerobot/bin/python scripts/lerobot_compat_check.py /path/to/dataset_root \
        [--compare-npz expected.npz] [--image-atol 0] [--image-mean-atol X] [--state-atol 0] \
        [--action-atol 0] [--delta-check] [--video-backend auto|torchcodec|pyav] \
        [--samples 0,10,-1] [--max-frames N]

Runs fully offline (sets HF_HUB_OFFLINE / HF_DATASETS_OFFLINE before importing LeRobot) and points
HF_DATASETS_CACHE at a temporary directory (removed at exit) unless --datasets-cache is given.
--video-backend auto uses torchcodec (LeRobot's default) when it can load system FFmpeg, else pyav.
--delta-check reloads with delta_timestamps (as LeRobot training does) and checks chunk values and
*_is_pad masks at episode boundaries. Images also get an alignment check: the run fails when most
decoded frames match the neighbouring expected frame better than their own (an off-by-one).
See docs/lerobot_v30_notes.md for the format and what LeRobot 0.4.4 requires.

The last line printed on stdout is one JSON object (the summary). Exit codes:
0 = loaded (and, with --compare-npz, everything within tolerance);
1 = comparison mismatch beyond tolerance;
2 = the dataset could not be loaded / read by LeRobot (error in the JSON summary).

``--compare-npz`` file layout (all arrays in global frame-index order, i.e. LeRobot's
``dataset[i]`` order):
  state            (N, D) float   -> compared with ``observation.state``
  action           (N, D) float   -> compared with ``action``
  images.<view>    (N, H, W, 3) uint8 -> compared with ``observation.images.<view>``
                   (LeRobot returns float32 CHW in [0, 1]; it is converted back with
                   round(x * 255) before comparing)
  optional: episode_index, frame_index, index, task_index (N,) ints and timestamp (N,)
  float (compared exactly / to 1e-6 s), task (N,) strings (compared exactly), and any key
  that is exactly a feature name of the dataset (compared with --state-atol).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import traceback
from pathlib import Path


def _parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("root", type=Path, help="dataset root (contains meta/, data/, videos/)")
    p.add_argument("--repo-id", default=None, help="repo_id passed to LeRobotDataset (default local/<dirname>)")
    p.add_argument(
        "--video-backend",
        default="auto",
        choices=["auto", "torchcodec", "pyav"],
        help="auto = LeRobot's default (torchcodec) if torchcodec can really load, else pyav",
    )
    p.add_argument("--tolerance-s", type=float, default=1e-4, help="LeRobotDataset tolerance_s (LeRobot default 1e-4)")
    p.add_argument("--samples", default=None, help="comma-separated frame indices to summarise (negative ok)")
    p.add_argument("--compare-npz", type=Path, default=None)
    p.add_argument("--image-atol", type=float, default=0.0, help="max abs diff allowed on uint8 pixels")
    p.add_argument(
        "--image-mean-atol",
        type=float,
        default=None,
        help="optional: also fail when a frame's MEAN abs pixel diff exceeds this (useful for lossy codecs, "
        "together with a loose --image-atol)",
    )
    p.add_argument("--state-atol", type=float, default=0.0)
    p.add_argument("--action-atol", type=float, default=0.0)
    p.add_argument("--max-frames", type=int, default=None, help="compare only the first N frames")
    p.add_argument(
        "--delta-check",
        action="store_true",
        help="also load with delta_timestamps (action chunk 0..4 frames, state/first camera -1..0 frame), as "
        "LeRobot training does, and check values and *_is_pad masks at episode boundaries",
    )
    p.add_argument(
        "--no-alignment-check",
        action="store_true",
        help="do not fail when most decoded images match a neighbouring expected frame better",
    )
    p.add_argument(
        "--datasets-cache",
        default=None,
        help="HF_DATASETS_CACHE to use (default: a fresh temporary dir, removed at exit)",
    )
    return p.parse_args(argv)


def _torchcodec_usable() -> tuple[bool, str]:
    try:
        import torchcodec  # noqa: F401
        from torchcodec.decoders import VideoDecoder  # noqa: F401

        return True, ""
    except Exception as e:
        return False, f"{type(e).__name__}: {str(e).splitlines()[0]}"


def _to_list(v):
    import numpy as np
    import torch

    if isinstance(v, torch.Tensor):
        v = v.detach().cpu().numpy()
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    return v


def _describe(key, v, feature):
    import torch

    if isinstance(v, torch.Tensor):
        if feature is not None and feature.get("dtype") in ("video", "image"):
            return {
                "shape": list(v.shape),
                "dtype": str(v.dtype).replace("torch.", ""),
                "min": float(v.min()),
                "max": float(v.max()),
                "mean": round(float(v.float().mean()), 6),
            }
        if v.ndim == 0:
            return _to_list(v)
        return [round(x, 6) if isinstance(x, float) else x for x in _to_list(v)]
    return v


def _image_to_uint8_hwc(t):
    import numpy as np

    a = t.detach().cpu().numpy()
    if a.ndim == 3:
        a = np.transpose(a, (1, 2, 0))  # LeRobot always returns CHW (video and image features)
    if a.dtype.kind == "f":
        a = np.clip(np.rint(a * 255.0), 0, 255)
    return a.astype(np.uint8)


def main(argv: list[str] | None = None) -> int:
    args = _parse_args(argv)
    os.environ["HF_HUB_OFFLINE"] = "1"
    os.environ["HF_DATASETS_OFFLINE"] = "1"
    os.environ.setdefault("HF_HUB_DISABLE_TELEMETRY", "1")
    tmp_cache = None
    if args.datasets_cache:
        os.environ["HF_DATASETS_CACHE"] = args.datasets_cache
    else:
        tmp_cache = tempfile.mkdtemp(prefix="lerobot_compat_hfds_")
        os.environ["HF_DATASETS_CACHE"] = tmp_cache

    summary: dict = {"ok": False, "root": str(args.root)}
    try:
        return _run(args, summary)
    except Exception as e:
        summary["error"] = f"{type(e).__name__}: {e}"
        summary["traceback"] = traceback.format_exc().splitlines()[-12:]
        print(json.dumps(summary, default=str))
        return 2
    finally:
        if tmp_cache:
            shutil.rmtree(tmp_cache, ignore_errors=True)


def _run(args: argparse.Namespace, summary: dict) -> int:
    import lerobot
    import torch
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    root = args.root.resolve()
    if not (root / "meta" / "info.json").exists():
        # LeRobot would fall back to the Hub here; refuse instead.
        raise FileNotFoundError(f"{root}/meta/info.json not found (LeRobot would try the Hub)")
    repo_id = args.repo_id or f"local/{root.name}"

    backend = args.video_backend
    tc_ok, tc_err = _torchcodec_usable()
    if backend == "auto":
        backend = "torchcodec" if tc_ok else "pyav"
    summary["lerobot_version"] = getattr(lerobot, "__version__", None)
    summary["torch_version"] = torch.__version__
    summary["video_backend"] = backend
    if not tc_ok:
        summary["torchcodec_unusable"] = tc_err

    ds = LeRobotDataset(repo_id, root=root, video_backend=backend, tolerance_s=args.tolerance_s)
    meta = ds.meta
    n = len(ds)
    summary.update(
        {
            "repo_id": repo_id,
            "codebase_version": meta.info.get("codebase_version"),
            "num_episodes": ds.num_episodes,
            "num_frames": ds.num_frames,
            "len": n,
            "fps": ds.fps,
            "video_keys": list(meta.video_keys),
            "features": {
                k: {"dtype": v["dtype"], "shape": list(v["shape"]), "names": v.get("names")}
                for k, v in meta.features.items()
            },
            "tasks": [str(t) for t in meta.tasks.index],
            "has_stats": meta.stats is not None,
        }
    )

    if args.samples:
        idxs = [int(s) for s in args.samples.split(",") if s.strip()]
    else:
        idxs = [0, n - 1]
        try:
            for ep in range(meta.total_episodes):
                e = meta.episodes[ep]
                idxs += [int(e["dataset_from_index"]), int(e["dataset_to_index"]) - 1]
        except KeyError as e:  # dataset_from_index/to_index missing: LeRobot's delta_timestamps would fail
            summary.setdefault("warnings", []).append(f"episodes metadata lacks {e}")
        idxs = idxs[:8]
    idxs = sorted({i % n for i in idxs}) if n else []
    samples = []
    for i in idxs:
        item = ds[i]
        samples.append({"i": i, **{k: _describe(k, v, meta.features.get(k)) for k, v in item.items()}})
    summary["samples"] = samples

    rc = 0
    if args.compare_npz is not None:
        cmp = _compare(ds, args)
        summary["compare"] = cmp
        if not cmp["ok"]:
            rc = 1
    if args.delta_check:
        dc = _delta_check(ds, repo_id, root, backend, args)
        summary["delta_check"] = dc
        if not dc["ok"]:
            rc = 1
    summary["ok"] = rc == 0
    print(json.dumps(summary, default=str))
    return rc


def _delta_check(ds, repo_id, root, backend, args) -> dict:
    """Load again with delta_timestamps and check chunks + padding at episode boundaries."""
    import numpy as np
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    meta = ds.meta
    fps = ds.fps
    vkeys = list(meta.video_keys)
    dts = {"action": [i / fps for i in range(5)], "observation.state": [-1 / fps, 0.0]}
    if vkeys:
        dts[vkeys[0]] = [-1 / fps, 0.0]
    dts = {k: v for k, v in dts.items() if k in meta.features}
    res: dict = {"ok": True, "delta_timestamps": dts, "checked": [], "problems": []}
    dsd = LeRobotDataset(repo_id, root=root, video_backend=backend, tolerance_s=args.tolerance_s, delta_timestamps=dts)
    ep_col = np.array([int(x) for x in dsd.hf_dataset["episode_index"]])
    n = len(ep_col)
    starts = [i for i in range(n) if i == 0 or ep_col[i] != ep_col[i - 1]]
    ends = [i for i in range(n) if i == n - 1 or ep_col[i] != ep_col[i + 1]]
    bounds = {int(ep_col[s]): (s, e + 1) for s, e in zip(starts, ends, strict=True)}
    idxs = sorted({i for s, e in bounds.values() for i in (s, min(s + 1, e - 1), max(e - 2, s), e - 1)})[:24]
    exp = np.load(args.compare_npz) if args.compare_npz is not None else None
    npz_key = {"action": "action", "observation.state": "state"}
    if vkeys:
        npz_key[vkeys[0]] = "images." + vkeys[0][len("observation.images.") :]
    for i in idxs:
        item = dsd[i]
        s, e = bounds[int(ep_col[i])]
        for key, deltas in dts.items():
            steps = [round(d * fps) for d in deltas]
            want_pad = [not (s <= i + d < e) for d in steps]
            got_pad = [bool(x) for x in item[f"{key}_is_pad"].tolist()]
            if got_pad != want_pad:
                res["problems"].append(f"[{i}] {key}_is_pad {got_pad} != expected {want_pad}")
            val = item[key]
            if val.shape[0] != len(steps):
                res["problems"].append(f"[{i}] {key} leading dim {val.shape[0]} != {len(steps)}")
                continue
            nk = npz_key.get(key)
            if exp is not None and nk in exp.files:
                for t, d in enumerate(steps):
                    j = min(max(i + d, s), e - 1)
                    if key in vkeys:
                        g = _image_to_uint8_hwc(val[t]).astype(np.int16)
                        diff = float(np.abs(g - exp[nk][j].astype(np.int16)).max())
                        tol = args.image_atol
                    else:
                        diff = float(np.abs(val[t].numpy().astype(np.float64) - exp[nk][j].astype(np.float64)).max())
                        tol = args.action_atol if key == "action" else args.state_atol
                    if diff > tol:
                        res["problems"].append(f"[{i}] {key}[{t}] (frame {j}) max abs diff {diff} > {tol}")
        res["checked"].append(i)
    res["ok"] = not res["problems"]
    res["problems"] = res["problems"][:20]
    return res


def _compare(ds, args) -> dict:
    import numpy as np
    import torch

    meta = ds.meta
    exp = np.load(args.compare_npz, allow_pickle=False)
    n_exp = None
    plan = []  # (npz_key, feature_key, kind, atol)
    for k in exp.files:
        arr = exp[k]
        n_exp = arr.shape[0] if n_exp is None else n_exp
        if k == "state":
            plan.append((k, "observation.state", "float", args.state_atol))
        elif k == "action":
            plan.append((k, "action", "float", args.action_atol))
        elif k.startswith("images."):
            plan.append((k, "observation.images." + k[len("images.") :], "image", args.image_atol))
        elif k == "task":
            plan.append((k, "task", "str", 0))
        elif k == "timestamp":
            plan.append((k, "timestamp", "float", 1e-6))
        elif k in ("episode_index", "frame_index", "index", "task_index"):
            plan.append((k, k, "int", 0))
        elif k in meta.features:
            kind = (
                "image"
                if meta.features[k]["dtype"] in ("video", "image")
                else ("str" if meta.features[k]["dtype"] == "string" else "float")
            )
            plan.append((k, k, kind, args.image_atol if kind == "image" else args.state_atol))
        else:
            plan.append((k, None, "skip", 0))

    res: dict = {"npz": str(args.compare_npz), "ok": True, "keys": {}, "problems": []}
    n = len(ds)
    if n_exp is not None and n_exp != n:
        res["ok"] = False
        res["problems"].append(f"frame count mismatch: npz {n_exp} vs dataset {n}")
    m = min(n, n_exp or 0)
    if args.max_frames is not None:
        m = min(m, args.max_frames)
    res["frames_compared"] = m

    acc = {
        k: {"max_abs_diff": 0.0, "sum_abs": 0.0, "count": 0, "first_bad_index": None, "closer_to_neighbour": 0}
        for k, *_ in plan
    }
    for i in range(m):
        item = ds[i]
        for k, fk, kind, atol in plan:
            if kind == "skip":
                continue
            a = acc[k]
            if fk not in item:
                res["problems"].append(f"{k}: feature {fk!r} not in dataset item")
                plan = [p for p in plan if p[0] != k]
                continue
            got = item[fk]
            want = exp[k][i]
            if kind == "str":
                bad = str(got) != str(want)
                d = float(bad)
                a["sum_abs"] += d
            elif kind == "image":
                g = _image_to_uint8_hwc(got).astype(np.int16)
                w = np.asarray(want).astype(np.int16)
                if g.shape != w.shape:
                    res["problems"].append(f"{k}[{i}]: shape {g.shape} vs expected {w.shape}")
                    a["first_bad_index"] = a["first_bad_index"] if a["first_bad_index"] is not None else i
                    continue
                diff = np.abs(g - w)
                d = float(diff.max())
                mad = float(diff.mean())
                a["sum_abs"] += mad
                # alignment check: is a neighbouring expected frame a strictly better match?
                for j in (i - 1, i + 1):
                    if 0 <= j < exp[k].shape[0]:
                        mad_j = float(np.abs(g - exp[k][j].astype(np.int16)).mean())
                        if mad_j < mad:
                            a["closer_to_neighbour"] += 1
                            break
                a["max_frame_mean_abs_diff"] = max(a.get("max_frame_mean_abs_diff", 0.0), mad)
                if args.image_mean_atol is not None and mad > args.image_mean_atol and a["first_bad_index"] is None:
                    a["first_bad_index"] = i
            else:
                g = got.detach().cpu().numpy() if isinstance(got, torch.Tensor) else np.asarray(got)
                g = np.asarray(g, dtype=np.float64).reshape(-1)
                w = np.asarray(want, dtype=np.float64).reshape(-1)
                if g.shape != w.shape:
                    res["problems"].append(f"{k}[{i}]: shape {g.shape} vs expected {w.shape}")
                    a["first_bad_index"] = a["first_bad_index"] if a["first_bad_index"] is not None else i
                    continue
                d = float(np.max(np.abs(g - w))) if g.size else 0.0
                a["sum_abs"] += float(np.mean(np.abs(g - w))) if g.size else 0.0
            a["count"] += 1
            a["max_abs_diff"] = max(a["max_abs_diff"], d)
            if d > atol and a["first_bad_index"] is None:
                a["first_bad_index"] = i

    for k, fk, kind, atol in plan:
        a = acc[k]
        entry = {"feature": fk, "kind": kind}
        if kind != "skip":
            entry.update(
                {
                    "atol": atol,
                    "max_abs_diff": a["max_abs_diff"],
                    "mean_abs_diff": (a["sum_abs"] / a["count"]) if a["count"] else None,
                    "frames": a["count"],
                    "first_bad_index": a["first_bad_index"],
                    "ok": a["first_bad_index"] is None and a["count"] == m,
                }
            )
            if kind == "image":
                # frames whose decoded image matches expected frame i-1 or i+1 better than frame i:
                # a sign of an off-by-one in timestamps / from_timestamp (fails the check)
                entry["frames_closer_to_neighbour"] = a["closer_to_neighbour"]
                entry["max_frame_mean_abs_diff"] = a.get("max_frame_mean_abs_diff")
                entry["mean_atol"] = args.image_mean_atol
                # lossy codecs can make a few frames look more like a neighbour; only a systematic
                # shift (more than half of the frames) fails the check
                if not args.no_alignment_check and a["count"] >= 2 and a["closer_to_neighbour"] * 2 > a["count"]:
                    entry["ok"] = False
                    entry["misaligned"] = True
            if not entry["ok"]:
                res["ok"] = False
        res["keys"][k] = entry
    if res["problems"]:
        res["ok"] = False
    return res


if __name__ == "__main__":
    sys.exit(main())
