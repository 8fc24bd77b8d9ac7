"""Export: labels → human_N outcomes, metrics.json recomputed with the human judges, report section."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pilworld.annotate.export import export_labels
from pilworld.annotate.server import AnnotationServer
from pilworld.annotate.store import DB_FILE, AnnotationStore, Label, StoreError
from pilworld.data.outcomes import read_outcomes
from pilworld.data.pairs import load_pairs
from pilworld.judges.hallucination_checks import CATEGORIES
from tests.pilworld.annotate.client import Client

FAST = {"single_step": False, "bootstrap": 0}
T = 16


def _label_through_the_api(srv: AnnotationServer) -> dict[tuple[str, int], tuple[bool, int | None]]:
    """Judge 1 labels all four episodes, judge 2 three; returns (judge id, episode) → (success, frame)."""
    truth: dict[tuple[str, int], tuple[bool, int | None]] = {}
    for judge, count in ((1, 4), (2, 3)):
        client = Client(srv.url, srv.tokens[judge])
        for n, item in enumerate(client.queue()[:count]):
            episode = srv.app.catalog.episode_of(judge, item)
            assert episode is not None
            success, frame = (episode + judge) % 2 == 0, (None if n % 2 else 2 + episode + judge)
            category = None if frame is None else CATEGORIES[n % len(CATEGORIES)]
            assert client.label(item, success, frame, category).status == 200
            truth[(f"human_{judge}", episode)] = (success, frame)
    return truth


def test_export_writes_outcomes_and_recomputes(run: Path) -> None:
    with AnnotationServer(run, judges=2) as srv:
        truth = _label_through_the_api(srv)
    result = export_labels(run, metrics_kwargs=FAST)
    assert result.labels == {"human_1": 4, "human_2": 3} and result.removed == 0
    rows = {(o.judge_id, o.episode_index): o for o in read_outcomes(run) if o.judge_kind == "human"}
    assert set(rows) == set(truth)
    for key, (success, frame) in truth.items():
        assert (rows[key].success, rows[key].first_hallucination_frame, rows[key].num_frames) == (success, frame, T)
    assert {o.judge_id for o in read_outcomes(run)} == {"human_1", "human_2", "sim_checker"}  # others kept

    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["judges"]["success"] == ["human_1", "human_2"]
    # the paper's formulas by hand: per pair the mean over its both-branch judges, then the mean over pairs
    paired = load_pairs(run)
    real, imag, hfr = [], [], []
    for p in paired.pairs:
        both = [j for j in ("human_1", "human_2") if (j, p.real) in truth and (j, p.imagined) in truth]
        real.append(np.mean([truth[(j, p.real)][0] for j in both]))
        imag.append(np.mean([truth[(j, p.imagined)][0] for j in both]))
        marks = [truth[(j, p.imagined)][1] for j in ("human_1", "human_2") if (j, p.imagined) in truth]
        hfr.append(np.mean([T if f is None else f for f in marks]) / T)
    overall = metrics["overall"]
    assert overall["sr_real"] == pytest.approx(np.mean(real), abs=1e-5)
    assert overall["sr_imag"] == pytest.approx(np.mean(imag), abs=1e-5)
    assert overall["hfr"] == pytest.approx(np.mean(hfr), abs=1e-5)
    agreement = metrics["human_agreement"]
    assert agreement["judges"] == ["human_1", "human_2"] and agreement["episodes_shared"] == 3
    assert agreement["human_only"]["overall"]["sr_real"] == pytest.approx(np.mean(real), abs=1e-5)
    assert "sim_checker" in agreement["vs_other_judges"]["human_1"]

    html = (run / "report.html").read_text()
    assert result.report == run / "report.html"
    assert 'id="human"' in html and 'id="human-agreement"' in html and "human_2" in html


def test_export_replaces_a_judges_rows_whole(run: Path) -> None:
    store = AnnotationStore(run)
    store.ensure_judges(2)
    for e in range(4):
        store.put_label(1, e, Label(True, None, None))
        store.put_label(2, e, Label(False, 1, CATEGORIES[0]))
    assert export_labels(run, metrics=False, report=False).labels == {"human_1": 4, "human_2": 4}
    # a fresh database (the old one deleted): judge 1 labelled one episode, judge 2 none yet
    for p in run.glob(f"{DB_FILE}*"):
        p.unlink()
    store = AnnotationStore(run)
    store.ensure_judges(2)
    store.put_label(1, 2, Label(False, None, None))
    result = export_labels(run, metrics=False, report=False)
    assert result.labels == {"human_1": 1, "human_2": 0} and result.removed == 7
    human = [o for o in read_outcomes(run) if o.judge_kind == "human"]
    assert [(o.judge_id, o.episode_index, o.success) for o in human] == [("human_1", 2, False)]


def test_export_needs_a_session(run: Path, tmp_path: Path) -> None:
    with pytest.raises(StoreError, match="annotate serve"):
        export_labels(run)
    with pytest.raises(ValueError, match="not a LeRobot dataset"):
        export_labels(tmp_path)
