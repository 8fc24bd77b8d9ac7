"""The report's HTML: one self-contained page (inline CSS, inline JS, media as ``data:`` URIs).

Nothing here reads files; :mod:`pilworld.report.build` gathers the data into :class:`PairView` and
:class:`PageData` and :func:`render_page` turns them into text. Every string from the run is escaped.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from html import escape
from typing import Any

from pilworld.report.agreement_view import agreement_section
from pilworld.report.judges_view import judges_section
from pilworld.report.metrics_view import DASH, fmt_with_ci

CHECK, CROSS = "✓", "✗"
TASK_COLUMNS = (
    ("sr_real", "SR real"),
    ("sr_imag", "SR imagined"),
    ("abs_delta_sr", "|ΔSR|"),
    ("hfr", "HFR"),
    ("sr_real_checker", "SR real, sim checker"),
)
DISPLAY_SCALE = 1.5  # the tile video is shown at 1.5× its pixel size (128 px tiles are small on screen)
RANK_COLUMNS = (("pearson", "Pearson r"), ("spearman", "Spearman ρ"), ("mmrv", "MMRV"))


@dataclass
class Verdict:
    """One judge's verdict on one branch, as shown."""

    judge_id: str
    judge_kind: str
    success: bool
    first_hallucination_frame: int | None
    num_frames: int


@dataclass
class PairView:
    """Everything shown for one pair."""

    index: int
    pair_id: str
    task: str
    instruction: str
    checkpoint: str
    seed: int
    subtask_index: int
    frames: int  # frames in the tile video (the longer branch)
    fps: float
    episodes: dict[str, int]  # origin → episode index
    seconds: dict[str, float]  # origin → branch wall time
    verdicts: dict[str, list[Verdict]]  # origin → verdicts
    rows: list[str]  # row labels of the tile, top to bottom
    round_starts: list[int] = field(default_factory=list)  # first frame of each round after the first
    video_uri: str = ""  # "" = left out (max_pairs)
    poster_uri: str = ""
    tile_size: tuple[int, int] = (0, 0)  # (width, height) of the video in pixels
    video_bytes: int = 0


@dataclass
class Chart:
    title: str
    png_uri: str
    caption: str
    alt: str


@dataclass
class PageData:
    title: str
    run_dir: str
    summary: list[tuple[str, str]]  # (label, value) lines of the run header
    metrics: Mapping[str, Any] | None
    metrics_note: str  # why there is no metrics table ("" when there is one)
    settings: list[tuple[str, str, float, float, int | None]]
    charts: list[Chart]
    chart_notes: list[str]
    pairs: list[PairView]
    left_out: int  # pairs shown without video
    max_pairs: int | None
    notes: list[str]  # anything the reader should know (Γ unavailable, branches missing, …)
    version: str


CSS = """
:root { --fg:#1d1d1f; --muted:#6b6b73; --line:#d9d9de; --bg:#fafafa; --card:#ffffff; --ok:#1a7f37;
        --bad:#c62828; --accent:#0b62c4; --hall:#e65100; }
* { box-sizing: border-box; }
body { margin: 0; padding: 24px 32px 64px; font: 14px/1.45 system-ui, -apple-system, "Segoe UI", Roboto,
       "DejaVu Sans", sans-serif; color: var(--fg); background: var(--bg); }
h1 { font-size: 22px; margin: 0 0 6px; } h2 { font-size: 18px; margin: 32px 0 10px; border-bottom: 1px solid
var(--line); padding-bottom: 4px; } h3 { font-size: 15px; margin: 0 0 8px; font-family: ui-monospace, monospace; }
nav a { margin-right: 14px; color: var(--accent); }
dl.summary { display: grid; grid-template-columns: max-content 1fr; gap: 2px 14px; margin: 10px 0; }
dl.summary dt { color: var(--muted); } dl.summary dd { margin: 0; }
table { border-collapse: collapse; background: var(--card); }
th, td { border: 1px solid var(--line); padding: 5px 10px; text-align: left; vertical-align: top; }
th { background: #f0f0f3; font-weight: 600; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
.ci { display: block; color: var(--muted); font-size: 11px; }
tr.overall td { font-weight: 600; }
.note, .missing { color: var(--muted); } .missing { font-style: italic; }
.charts { display: flex; flex-wrap: wrap; gap: 18px; align-items: flex-start; }
figure { margin: 0; background: var(--card); border: 1px solid var(--line); padding: 10px; }
figure img { display: block; max-width: 100%; }
figcaption { color: var(--muted); font-size: 12px; max-width: 620px; margin-top: 6px; }
article.pair { background: var(--card); border: 1px solid var(--line); border-radius: 6px; padding: 14px 16px;
               margin: 0 0 18px; }
.pair-body { display: flex; flex-wrap: wrap; gap: 24px; align-items: flex-start; }
.player { display: grid; grid-template-columns: auto var(--vw); gap: 0 6px; }
.colheads { display: flex; grid-column: 2; } .colheads span { flex: 1; text-align: center; font-weight: 600; }
.rowlabels { display: flex; flex-direction: column; grid-column: 1; width: 92px; }
.rowlabels span { flex: 1; display: flex; align-items: center; justify-content: flex-end; text-align: right;
                  font-size: 12px; color: var(--muted); }
video { display: block; width: var(--vw); height: auto; background: #303030; image-rendering: pixelated; }
.timeline { grid-column: 2; position: relative; height: 22px; margin-top: 6px; background: #e8e8ec;
            border-radius: 3px; cursor: pointer; }
.timeline .tick { position: absolute; top: 0; bottom: 0; width: 1px; background: #b8b8c0; }
.timeline .playhead { position: absolute; top: -2px; bottom: -2px; width: 2px; background: var(--accent);
                      left: 0; }
.timeline button.hmark { position: absolute; top: 1px; width: 12px; height: 20px; margin-left: -6px; padding: 0;
                         border: 0; border-radius: 2px; background: var(--hall); cursor: pointer; }
.timeline button.hmark.real { background: #8e24aa; }
.frameinfo { grid-column: 2; font-size: 12px; color: var(--muted); margin-top: 3px; font-variant-numeric:
             tabular-nums; }
.hinfo { margin: 6px 0 0; } .hinfo a, table.outcomes a { color: var(--hall); font-weight: 600; }
.ok { color: var(--ok); font-weight: 700; } .bad { color: var(--bad); font-weight: 700; }
.novideo { color: var(--muted); font-style: italic; margin: 6px 0; }
dl.labels { display: grid; grid-template-columns: max-content 1fr; gap: 1px 10px; margin: 0 0 10px; font-size: 13px; }
dl.labels dt { color: var(--muted); } dl.labels dd { margin: 0; }
"""

JS = """
(function () {
  document.body.setAttribute('data-js', 'ran');
  var ready = 0;
  function pad(f, fps) { return 'frame ' + f + ' · ' + (f / fps).toFixed(2) + ' s'; }
  document.querySelectorAll('article.pair').forEach(function (pair) {
    var video = pair.querySelector('video');
    var bar = pair.querySelector('.timeline');
    if (!video || !bar) return;
    var T = +bar.dataset.frames, fps = +bar.dataset.fps;
    var head = bar.querySelector('.playhead'), info = pair.querySelector('.frameinfo');
    function show(f) {
      head.style.left = ((f + 0.5) / T * 100) + '%';
      if (info) info.textContent = pad(f, fps) + ' of ' + T + ' frames';
    }
    function seek(f) {
      f = Math.max(0, Math.min(T - 1, f));
      video.pause();
      video.currentTime = (f + 0.5) / fps;  // mid-frame, so rounding cannot land on the previous frame
      show(f);
    }
    pair.querySelectorAll('[data-seek]').forEach(function (el) {
      el.addEventListener('click', function (ev) {
        ev.preventDefault(); ev.stopPropagation(); seek(+el.dataset.seek);
      });
    });
    bar.addEventListener('click', function (ev) {
      var r = bar.getBoundingClientRect();
      seek(Math.floor((ev.clientX - r.left) / r.width * T));
    });
    video.addEventListener('timeupdate', function () {
      show(Math.min(T - 1, Math.floor(video.currentTime * fps)));
    });
    video.addEventListener('loadedmetadata', function () {
      video.setAttribute('data-decoded', video.videoWidth + 'x' + video.videoHeight);
      ready += 1;
      document.body.setAttribute('data-videos-ready', String(ready));
    });
    video.addEventListener('error', function () {
      video.setAttribute('data-error', video.error ? String(video.error.code) : 'unknown');
    });
  });
})();
"""


def _e(value: object) -> str:
    return escape(str(value), quote=True)


def _seconds(frame: int, fps: float) -> str:
    return f"{frame / fps:.2f} s"


def _value_cells(entry: Mapping[str, Any], columns: Sequence[tuple[str, str]], digits: int) -> str:
    """``<td>`` per column: the value, its 95 % interval below, and metrics.json's reason when it is missing."""
    cells = []
    for key, _ in columns:
        value, ci = fmt_with_ci(entry, key, digits)
        reason = entry.get(f"{key}_reason")
        title = f' title="{_e(reason)}"' if isinstance(reason, str) and reason else ""
        ci_html = f'<span class="ci">{_e(ci)}</span>' if ci else ""
        cells.append(f'<td class="num"{title}>{_e(value)}{ci_html}</td>')
    return "".join(cells)


def _metrics_section(page: PageData) -> str:
    out = ['<section id="metrics"><h2>Metrics</h2>']
    m = page.metrics
    if m is None:
        out.append(f'<p class="missing" id="metrics-missing">{_e(page.metrics_note)}</p></section>')
        return "".join(out)
    head = "".join(f"<th>{_e(label)}</th>" for _, label in TASK_COLUMNS)
    out.append(f'<table id="metrics-table" class="metrics"><thead><tr><th>task</th>{head}</tr></thead><tbody>')
    tasks = m.get("tasks")
    rows: list[tuple[str, Mapping[str, Any], str]] = []
    if isinstance(tasks, Mapping):
        rows += [(str(t), v, "") for t, v in tasks.items() if isinstance(v, Mapping)]
    overall = m.get("overall") if isinstance(m.get("overall"), Mapping) else None
    if overall is not None:
        rows.append(("overall", overall, ' class="overall"'))
    if not rows:
        out.append(f'<tr><td colspan="{len(TASK_COLUMNS) + 1}" class="missing">no per-task metrics</td></tr>')
    for name, entry, cls in rows:
        out.append(f"<tr{cls}><td>{_e(name)}</td>{_value_cells(entry, TASK_COLUMNS, 2)}</tr>")
    out.append("</tbody></table>")
    head = "".join(f"<th>{_e(label)}</th>" for _, label in RANK_COLUMNS)
    rank_rows = [("all settings", overall or {})]
    if isinstance(tasks, Mapping) and len(tasks) > 1:
        for t, v in tasks.items():
            across = v.get("across_checkpoints") if isinstance(v, Mapping) else None
            if isinstance(across, Mapping):
                rank_rows.append((f"{t}: its checkpoints", across))
    body = "".join(f"<tr><td>{_e(n)}</td>{_value_cells(e, RANK_COLUMNS, 3)}</tr>" for n, e in rank_rows)
    out.append(
        '<p class="note">Ranking agreement across task × checkpoint settings (imagined vs real success rates):</p>'
        f'<table id="rank-table" class="metrics"><thead><tr><th>settings</th>{head}</tr></thead><tbody>{body}'
        "</tbody></table>"
    )
    out.append(
        '<p class="note">SR: success rate; |ΔSR|: absolute gap between real and imagined SR; HFR: hallucination-free '
        "ratio (mean t<sub>h</sub>/T of the imagined branch); SR real, sim checker: the simulator's privileged "
        "verdicts alone; MMRV: mean maximum rank violation. Brackets: 95 % "
        "interval from metrics.json. —: not in metrics.json or undefined (hover for the reason).</p>"
    )
    if page.metrics_note:
        out.append(f'<p class="missing">{_e(page.metrics_note)}</p>')
    out.append("</section>")
    return "".join(out)


def _charts_section(page: PageData) -> str:
    out = ['<section id="charts"><h2>Real vs imagined</h2><div class="charts">']
    for c in page.charts:
        out.append(
            f'<figure class="chart"><img alt="{_e(c.alt)}" src="{c.png_uri}">'
            f"<figcaption><b>{_e(c.title)}.</b> {_e(c.caption)}</figcaption></figure>"
        )
    out.append("</div>")
    out += [f'<p class="missing">{_e(n)}</p>' for n in page.chart_notes]
    if page.settings:
        out.append(
            '<table id="settings-table"><thead><tr><th>task</th><th>checkpoint</th><th>SR real</th>'
            "<th>SR imagined</th><th>n</th></tr></thead><tbody>"
        )
        for task, ckpt, real, imag, n in page.settings:
            out.append(
                f'<tr><td>{_e(task)}</td><td>{_e(ckpt)}</td><td class="num">{real:.2f}</td>'
                f'<td class="num">{imag:.2f}</td><td class="num">{_e(DASH if n is None else n)}</td></tr>'
            )
        out.append("</tbody></table>")
    out.append("</section>")
    return "".join(out)


def _verdict_cell(v: Verdict | None, fps: float) -> str:
    if v is None:
        return f'<td class="missing">{DASH}</td>'
    mark = f'<span class="ok">{CHECK}</span>' if v.success else f'<span class="bad">{CROSS}</span>'
    word = "success" if v.success else "failure"
    extra = ""
    if v.first_hallucination_frame is not None:
        f = v.first_hallucination_frame
        extra = f' · <a href="#" data-seek="{f}">hallucination at frame {f} ({_seconds(f, fps)})</a>'
    return f'<td title="{_e(v.judge_kind)}">{mark} {word}{extra}</td>'


def _outcomes_table(p: PairView, branches: Sequence[str]) -> str:
    judges = sorted({v.judge_id for vs in p.verdicts.values() for v in vs})
    head = "".join(f"<th>{_e(b)}</th>" for b in branches)
    out = [f'<table class="outcomes"><thead><tr><th>judge</th>{head}</tr></thead><tbody>']
    if not judges:
        out.append(f'<tr><td colspan="{len(branches) + 1}" class="missing">not judged yet</td></tr>')
    for judge in judges:
        cells = "".join(
            _verdict_cell(next((v for v in p.verdicts.get(b, []) if v.judge_id == judge), None), p.fps)
            for b in branches
        )
        out.append(f"<tr><td>{_e(judge)}</td>{cells}</tr>")
    out.append("</tbody></table>")
    return "".join(out)


def _hallucinations(p: PairView) -> list[tuple[str, Verdict]]:
    return [
        (branch, v)
        for branch, vs in p.verdicts.items()
        for v in vs
        if v.first_hallucination_frame is not None
    ]  # fmt: skip


def _player(p: PairView, branches: Sequence[str]) -> str:
    display_w = round(p.tile_size[0] * DISPLAY_SCALE)
    heads = "".join(f"<span>{_e(b)}</span>" for b in branches)
    labels = "".join(f"<span>{_e(r)}</span>" for r in p.rows)
    T = max(1, p.frames)
    ticks = "".join(f'<div class="tick" style="left:{100 * f / T:.3f}%"></div>' for f in p.round_starts)
    marks = "".join(
        f'<button type="button" class="hmark {_e(b)}" data-seek="{v.first_hallucination_frame}" '
        f'style="left:{100 * (v.first_hallucination_frame + 0.5) / T:.3f}%" '
        f'title="first hallucination ({_e(b)}, {_e(v.judge_id)}): frame {v.first_hallucination_frame}"></button>'
        for b, v in _hallucinations(p)
        if v.first_hallucination_frame is not None
    )
    return (
        f'<div class="player" style="--vw:{display_w}px">'
        f'<div class="colheads">{heads}</div>'
        f'<div class="rowlabels">{labels}</div>'
        f'<video class="pair-video" controls muted loop playsinline preload="auto" width="{display_w}" '
        f'data-frames="{p.frames}" data-fps="{p.fps:g}" data-pair="{_e(p.pair_id)}" '
        f'poster="{p.poster_uri}" src="{p.video_uri}"></video>'
        f'<div class="timeline" data-frames="{T}" data-fps="{p.fps:g}" title="click to seek">{ticks}{marks}'
        '<div class="playhead"></div></div>'
        f'<div class="frameinfo">frame 0 · 0.00 s of {T} frames ({p.fps:g} fps; ticks: rounds)</div>'
        "</div>"
    )


def _pair_article(p: PairView, branches: Sequence[str], max_pairs: int | None) -> str:
    labels = [
        ("task", p.task),
        ("instruction", p.instruction),
        ("checkpoint", p.checkpoint),
        ("seed", str(p.seed)),
        ("subtask", str(p.subtask_index)),
        ("episodes", ", ".join(f"{b} #{p.episodes[b]}" for b in branches if b in p.episodes)),
        ("frames", f"{p.frames} at {p.fps:g} fps ({_seconds(p.frames, p.fps)})"),
    ]
    if p.seconds:
        labels.append(("wall time", ", ".join(f"{b} {p.seconds[b]:.1f} s" for b in branches if b in p.seconds)))
    missing = [b for b in branches if b not in p.episodes]
    if missing:
        labels.append(("not recorded", ", ".join(missing)))
    dl = "".join(f"<dt>{_e(k)}</dt><dd>{_e(v)}</dd>" for k, v in labels)
    out = [f'<article class="pair" id="pair-{p.index}" data-pair="{_e(p.pair_id)}"><h3>{_e(p.pair_id)}</h3>']
    out.append('<div class="pair-body">')
    if p.video_uri:
        out.append(_player(p, branches))
    else:
        out.append(f'<p class="novideo">video left out (max_pairs = {_e(max_pairs)})</p>')
    out.append(f'<div><dl class="labels">{dl}</dl>{_outcomes_table(p, branches)}')
    halls = _hallucinations(p)
    for b, v in halls:
        f = v.first_hallucination_frame
        assert f is not None
        out.append(
            f'<p class="hinfo">First hallucination ({_e(b)}, judge {_e(v.judge_id)}): '
            f'<a href="#" data-seek="{f}">frame {f} · {_seconds(f, p.fps)}</a></p>'
        )
    if not halls and any(p.verdicts.values()):
        out.append('<p class="hinfo note">No hallucination marked by any judge.</p>')
    out.append("</div></div></article>")
    return "".join(out)


def render_page(page: PageData, branches: Sequence[str]) -> str:
    """The whole report as one HTML string."""
    summary = "".join(f"<dt>{_e(k)}</dt><dd>{_e(v)}</dd>" for k, v in page.summary)
    shown = sum(1 for p in page.pairs if p.video_uri)
    pairs_note = f"{len(page.pairs)} pairs"
    if page.left_out:
        pairs_note += (
            f"; {shown} shown with video, {page.left_out} left out (max_pairs = {page.max_pairs}; "
            "rerun without --max-pairs to embed all)"
        )
    body = [
        "<header>",
        f"<h1>{_e(page.title)}</h1>",
        f'<dl class="summary">{summary}</dl>',
        '<nav><a href="#metrics">metrics</a><a href="#judges">judges</a><a href="#charts">charts</a>'
        '<a href="#pairs">pairs</a></nav>',
        "</header>",
    ]
    body += [f'<p class="note">{_e(n)}</p>' for n in page.notes]
    body.append(_metrics_section(page))
    body.append(judges_section(page.metrics))  # "" without a judges block
    body.append(agreement_section(page.metrics))  # "" without human verdicts
    body.append(_charts_section(page))
    body.append(
        f'<section id="pairs"><h2>Pairs</h2><p class="note" id="pairs-note" data-left-out="{page.left_out}">'
        f"{_e(pairs_note)}. Each video: rows are the camera views and the control video Γ, the left column is the "
        "real branch and the right one the imagined branch; frame 0 is the shared start. Marks on the bar under a "
        "video: the first hallucination frame per judge, orange in the imagined branch, purple in the real one "
        "(click a mark, or anywhere on the bar, to seek; thin ticks: round starts).</p>"
    )
    body += [_pair_article(p, branches, page.max_pairs) for p in page.pairs]
    body.append("</section>")
    body.append(f'<footer class="note"><p>Generated by pilworld {_e(page.version)} (pilworld report).</p></footer>')
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{_e(page.title)}</title><style>{CSS}</style></head>\n<body>\n"
        + "\n".join(body)
        + f"\n<script>{JS}</script>\n</body></html>\n"
    )


__all__ = ["Chart", "PageData", "PairView", "Verdict", "render_page"]
