"""``build_report(run_dir)``: a paired run folder → one self-contained ``report.html``.

The page opens offline from a single file: videos and posters are ``data:`` URIs, charts are PNG data
URIs, CSS and JS are inline, and no ``http(s)`` address appears anywhere. Per pair it shows the real and
imagined videos side by side for every view plus the control video Γ (rebuilt from the stored actions),
the verdicts per judge and the first hallucination frame; for the run, the metrics of ``metrics.json``,
the real-vs-imagined success scatter with the Pearson line, and per-frame error curves.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

import pilworld
from pilworld.config.rig import RigConfig
from pilworld.control_video.gamma import ControlVideo
from pilworld.data.episode import Episode
from pilworld.io.atomic import atomic_write
from pilworld.report import charts
from pilworld.report.media import (
    CONTROL_ROW,
    control_frames,
    data_uri,
    frame_mse,
    mp4_bytes,
    ordered_views,
    png_bytes,
    psnr_of_mse,
    tile,
)
from pilworld.report.metrics_view import scalar, settings_points, single_step_curves
from pilworld.report.page import Chart, PageData, PairView, Verdict, render_page
from pilworld.report.run import BRANCHES, METRICS_FILE, PairInfo, RunData, read_run
from pilworld.types import ChunkSpec

REPORT_FILE = "report.html"
DEFAULT_CRF = 23  # H.264 quality: 23 keeps 128 px sim frames clean at ~10–20 kB per second of tile video


def _rig_path(value: str, run_dir: Path) -> Path | None:
    """The rig config named in paired_config.json: as given, else beside the checkout, else in the run folder."""
    p = Path(value)
    candidates = [p] if p.is_absolute() else [p, Path(pilworld.__file__).resolve().parents[1] / p, run_dir / p]
    return next((c for c in candidates if c.is_file()), None)


def _gamma(data: RunData, rig: RigConfig | None = None) -> tuple[ControlVideo | None, str]:
    """Γ of the run's rig (``rig``: already loaded by the caller) and chunk spec, or (None, why not)."""
    cfg = data.config
    if cfg is None:
        return None, "control video Γ not shown: paired_config.json is missing (the rig is unknown)"
    try:
        if rig is None:  # the rig the run's settings name, when the caller has none loaded
            rig_value = cfg.get("rig")
            if not isinstance(rig_value, str) or not rig_value:
                return None, "control video Γ not shown: paired_config.json names no rig"
            path = _rig_path(rig_value, data.root)
            if path is None:
                return None, f"control video Γ not shown: rig config {rig_value!r} not found"
            rig = RigConfig.load(path)
        spec_json = cfg.get("spec")
        spec = ChunkSpec(**spec_json) if isinstance(spec_json, Mapping) else ChunkSpec()
        return ControlVideo.from_rig(rig, spec), ""
    except (ValueError, TypeError, OSError) as err:
        return None, f"control video Γ not shown: {err}"


def _verdicts(data: RunData, info: PairInfo) -> dict[str, list[Verdict]]:
    return {
        branch: [
            Verdict(o.judge_id, o.judge_kind, o.success, o.first_hallucination_frame, o.num_frames)
            for o in data.outcomes.get(index, [])
        ]
        for branch, index in info.episodes.items()
    }


def _round_starts(episode: Episode) -> list[int]:
    rounds = episode.rounds()
    return [int(i) for i in np.nonzero(np.diff(rounds) != 0)[0] + 1 if i > 1]


class _ErrorAccumulator:
    """Real-vs-imagined squared error per view and frame index, pooled over pairs."""

    def __init__(self) -> None:
        self.sums: dict[str, NDArray[np.float64]] = {}
        self.counts: dict[str, NDArray[np.float64]] = {}

    def add(self, view: str, mse: NDArray[np.float64]) -> None:
        n = len(mse)
        s = self.sums.setdefault(view, np.zeros(0))
        c = self.counts.setdefault(view, np.zeros(0))
        if len(s) < n:
            s, c = np.pad(s, (0, n - len(s))), np.pad(c, (0, n - len(c)))
        ok = np.isfinite(mse)
        s[:n][ok] += mse[ok]
        c[:n][ok] += 1
        self.sums[view], self.counts[view] = s, c

    def psnr(self) -> dict[str, list[float | None]]:
        out: dict[str, list[float | None]] = {}
        for view, s in self.sums.items():
            c = self.counts[view]
            with np.errstate(invalid="ignore"):
                values = psnr_of_mse(s / np.maximum(c, 1))
            out[view] = [float(v) if c[i] > 0 and math.isfinite(v) else None for i, v in enumerate(values)]
        return out


def _pair_view(
    data: RunData,
    info: PairInfo,
    index: int,
    views: list[str],
    gamma: ControlVideo | None,
    errors: _ErrorAccumulator,
    embed: bool,
    crf: int,
) -> PairView:
    fps = float(data.store.fps)
    episodes = {b: data.store.load(i, views) for b, i in info.episodes.items()}
    if "real" in episodes and "imagined" in episodes:
        for v in views:
            errors.add(v, frame_mse(episodes["real"].images[v], episodes["imagined"].images[v]))
    rows = [*views, CONTROL_ROW] if gamma is not None else list(views)
    any_ep = next(iter(episodes.values()))
    view = PairView(
        index=index,
        pair_id=info.pair_id,
        task=info.task,
        instruction=info.instruction,
        checkpoint=info.checkpoint,
        seed=info.seed,
        subtask_index=info.subtask_index,
        frames=max(e.length for e in episodes.values()),
        fps=fps,
        episodes=dict(info.episodes),
        seconds=dict(info.seconds),
        verdicts=_verdicts(data, info),
        rows=rows,
        round_starts=_round_starts(any_ep),
    )
    if not embed:
        return view
    size = any_ep.images[views[0]].shape[1:3]
    cells: dict[str, dict[str, NDArray[np.uint8]]] = {}
    for branch, ep in episodes.items():
        cells[branch] = {v: ep.images[v] for v in views}
        if gamma is not None:
            cells[branch][CONTROL_ROW] = control_frames(ep, gamma)
    frames = tile(cells, BRANCHES, rows, (int(size[0]), int(size[1])))
    video = mp4_bytes(frames, fps=fps, crf=crf)
    view.video_uri = data_uri("video/mp4", video)
    view.video_bytes = len(video)
    view.poster_uri = data_uri("image/png", png_bytes(frames[-1]))
    view.tile_size = (int(frames.shape[2]), int(frames.shape[1]))
    return view


def _charts(
    data: RunData, closed_loop: dict[str, list[float | None]]
) -> tuple[list[Chart], list[str], list[tuple[str, str, float, float, int | None]]]:
    out: list[Chart] = []
    notes: list[str] = []
    m = data.metrics
    settings = settings_points(m) if m is not None else []
    if m is None:
        notes.append("Success scatter: needs metrics.json (its per-setting success rates).")
    elif not settings:
        notes.append("Success scatter: metrics.json lists no settings with both success rates.")
    else:
        overall = m.get("overall") if isinstance(m.get("overall"), Mapping) else {}
        assert isinstance(overall, Mapping)
        if "pearson" in overall:  # metrics.json's own value, or null with a reason: never second-guessed
            r, why = scalar(overall.get("pearson")), str(overall.get("pearson_reason") or "")
        else:
            r, why = charts.pearson([s[2] for s in settings], [s[3] for s in settings]), "too few distinct points"
        multi_task = len({s[0] for s in settings}) > 1
        points = [(f"{t}/{c}" if multi_task else c, x, y) for t, c, x, y, _ in settings]
        if r is not None:
            r_text = f"Pearson r = {r:.3f}"
        else:
            r_text = f"Pearson r undefined: {why}" if why else "Pearson r undefined"
        out.append(
            Chart(
                "Success rate, real vs imagined",
                data_uri("image/png", charts.success_scatter(points, r)),
                f"One point per task × checkpoint setting ({len(settings)}); "
                + (
                    f"red: least-squares line ({r_text}); "
                    if charts.has_fit_line([s[2] for s in settings])
                    else f"no least-squares line (needs two different real success rates; {r_text}); "
                )
                + "dashed: y = x, where a perfect world model's points lie.",
                "scatter of real against imagined success rates",
            )
        )
    single = single_step_curves(m.get("single_step")) if m is not None else {}
    if single:
        frozen = any("frozen" in label for series in single.values() for label in series)
        out.append(
            Chart(
                "Single-step error per frame",
                data_uri(
                    "image/png",
                    charts.error_curves(
                        single, "single-step prediction (metrics.json)", "predicted frame k", first_x=1
                    ),
                ),
                "World-model prediction of round 0 from the real start and the real branch's commands, against the "
                "real frames, per predicted frame k = 1..K (metrics.json single_step; per view where it has per-view "
                "curves)." + (" Frozen baseline: the start frame copied K times." if frozen else ""),
                "single-step PSNR and SSIM per frame index and view",
            )
        )
    else:
        notes.append("Single-step error curves: " + ("no per-frame values in metrics.json single_step." if m else
                                                      "need metrics.json."))  # fmt: skip
    ppi_chart = _ppi_chart(m)
    if ppi_chart is not None:
        out.append(ppi_chart)
    elif m is not None:
        reason = (m.get("ppi") or {}).get("reason") if isinstance(m.get("ppi"), Mapping) else None
        notes.append(f"Real success rate by PPI++: {reason or 'no ppi section in metrics.json'}.")
    if any(any(v is not None for v in vals) for vals in closed_loop.values()):
        out.append(
            Chart(
                "Closed-loop divergence per frame",
                data_uri(
                    "image/png",
                    charts.error_curves({"psnr": closed_loop}, "real vs imagined branch (this run)", "frame"),
                ),
                "PSNR of the imagined frame against the real frame at the same index, pooled over the pairs "
                "(mean squared error over pairs, then PSNR); frame 0 is the shared start and is left out. Unlike "
                "the single-step error, this includes the policy acting differently in each branch.",
                "closed-loop PSNR of imagined vs real frames per frame index and view",
            )
        )
    return out, notes, settings


def _ppi_chart(m: Mapping[str, Any] | None) -> Chart | None:
    section = m.get("ppi") if m is not None else None
    if not isinstance(section, Mapping):
        return None
    rows = [
        (str(c), e["classical"], e["ppi"], int(e["n"]), int(e["N"]))
        for c, e in section.get("checkpoints", {}).items()
        if isinstance(e, Mapping) and "ppi" in e
    ]
    if not rows:
        return None
    gains = ", ".join(f"{c} ×{float(section['checkpoints'][c]['ess_gain']):.2f}" for c, *_ in rows)
    return Chart(
        "Real success rate by PPI++",
        data_uri("image/png", charts.ppi_intervals(rows)),
        "Per checkpoint, the 95 % interval of the real success rate from the n paired subtasks' real outcomes alone "
        "(grey) and with the N imagined-only subtasks added by prediction-powered inference (blue; PPI++ with power "
        f"tuning, {section.get('method')} interval). Effective sample size gain per real trial: {gains}.",
        "classical and prediction-powered intervals of the real success rate per checkpoint",
    )


def _summary(data: RunData, views: list[str], pairs: int) -> list[tuple[str, str]]:
    cfg = data.config or {}
    spec = cfg.get("spec") if isinstance(cfg.get("spec"), Mapping) else {}
    assert isinstance(spec, Mapping)
    origins: dict[str, int] = {}
    for row in data.store.episodes:
        origins[str(row.get("origin"))] = origins.get(str(row.get("origin")), 0) + 1
    lines = [
        ("run folder", str(data.root)),
        ("task", str(cfg.get("task", "—"))),
        ("checkpoints", ", ".join(str(c) for c in cfg.get("checkpoints", [])) or "—"),
        ("pairs", f"{pairs} ({', '.join(f'{o} {n}' for o, n in sorted(origins.items()))} episodes)"),
        ("rig", str(cfg.get("rig", "—"))),
        ("world model", f"{cfg.get('world_model') or 'packaged'}, adapter {cfg.get('adapter', '—')}"),
        (
            "chunks",
            f"R = {spec.get('rounds', '—')} rounds of K = {spec.get('frames', '—')} frames at stride "
            f"Δ = {spec.get('stride', '—')}"
            if spec
            else "—",
        ),
        ("views", ", ".join(views)),
        ("frame rate", f"{data.store.fps} fps"),
    ]
    return lines


def build_report(
    run_dir: str | Path,
    out: str | Path | None = None,
    *,
    max_pairs: int | None = None,
    crf: int = DEFAULT_CRF,
    rig: RigConfig | None = None,
) -> Path:
    """Write the run's ``report.html`` (or ``out``); returns its path.

    ``max_pairs`` caps the pairs embedded with video (the first ones, in run order; default all); the rest
    are listed with their verdicts and the page says how many videos were left out.
    """
    if max_pairs is not None and (isinstance(max_pairs, bool) or not isinstance(max_pairs, int) or max_pairs < 0):
        raise ValueError(f"max_pairs: expected None or an integer >= 0, got {max_pairs!r}")
    if not 0 <= crf <= 51:
        raise ValueError(f"crf: expected an H.264 quality 0..51, got {crf!r}")
    data = read_run(run_dir)
    target = Path(out) if out is not None else data.root / REPORT_FILE
    views = ordered_views(list(data.store.spec.views))
    if not views:
        raise ValueError(f"RUN_DIR: {data.root} has no camera views")
    gamma, gamma_note = _gamma(data, rig)
    errors = _ErrorAccumulator()
    pairs = [
        _pair_view(data, info, i, views, gamma, errors, max_pairs is None or i < max_pairs, crf)
        for i, info in enumerate(data.pairs)
    ]
    chart_list, chart_notes, settings = _charts(data, errors.psnr())
    notes = [gamma_note] if gamma_note else []
    incomplete = [p.pair_id for p in data.pairs if p.missing]
    if incomplete:
        notes.append(f"{len(incomplete)} pair(s) have only one branch stored (a run in progress?): the other is blank.")
    if data.metrics is None:
        metrics_note = data.metrics_error or (
            f"{METRICS_FILE} not found in {data.root}: the metrics table and the success scatter appear once the "
            "run's metrics are computed (pilworld.metrics writes metrics.json into the run folder)."
        )
    else:
        metrics_note = ""
    left_out = sum(1 for p in pairs if not p.video_uri)
    page = PageData(
        title=f"PiL-World paired run — {data.root.resolve().name}",
        run_dir=str(data.root),
        summary=_summary(data, views, len(pairs)),
        metrics=data.metrics,
        metrics_note=metrics_note,
        settings=settings,
        charts=chart_list,
        chart_notes=chart_notes,
        pairs=pairs,
        left_out=left_out,
        max_pairs=max_pairs,
        notes=notes,
        version=pilworld.__version__,
    )
    text = render_page(page, BRANCHES)
    atomic_write(target, lambda tmp: tmp.write_text(text, encoding="utf-8"), durable=False)
    return target


def report_stats(path: str | Path) -> dict[str, Any]:
    """Size of a written report and how many videos it embeds (for the CLI's summary line)."""
    text = Path(path).read_text(encoding="utf-8")
    return {"path": str(path), "bytes": len(text.encode("utf-8")), "videos": text.count("<video ")}


__all__ = ["REPORT_FILE", "build_report", "report_stats"]
