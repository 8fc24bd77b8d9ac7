"""The rollout strip of one pair across variants: the frames it picks, the image, and its errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pilworld.bench.variant_strip import main, round_ends, runs_of, variant_strip
from pilworld.data.outcomes import Outcome, record_outcomes
from tests.pilworld.metrics.synthetic import ROUNDS, K, SynthPair, write_paired

PNG = b"\x89PNG\r\n\x1a\n"


def test_round_ends_are_the_start_and_each_rounds_last_frame() -> None:
    rounds = np.concatenate([[0], np.repeat(np.arange(3), 4)])
    assert round_ends(rounds) == [0, 4, 8, 12]
    with pytest.raises(ValueError, match="no frames"):
        round_ends(np.zeros(0, np.int64))


def _bench(root: Path) -> Path:
    pairs = [SynthPair(subtask=0), SynthPair(subtask=1, offset=30)]
    for name in ("pilworld", "v2_render"):
        run = write_paired(root / name, pairs)
        record_outcomes(run, [Outcome(e, "vision_v1", "vision", e % 3 == 0, 1 + ROUNDS * K) for e in range(4)])
    return root


def test_the_strip_has_a_row_per_variant_and_a_column_per_round(tmp_path: Path) -> None:
    import matplotlib.image as mpimg

    bench = _bench(tmp_path / "bench")
    runs = runs_of(bench)
    assert list(runs) == ["pilworld", "v2_render"]
    one = variant_strip({"pilworld": runs["pilworld"]}, SynthPair().pair_id, tmp_path / "one.png")
    both = variant_strip(runs, SynthPair().pair_id, tmp_path / "both.png")
    assert both.read_bytes()[:8] == PNG
    # one more variant is one more row: the image grows in height, not in width
    h1, w1 = mpimg.imread(one).shape[:2]
    h2, w2 = mpimg.imread(both).shape[:2]
    assert h2 > h1 and w2 == w1


def test_bad_input_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bench = _bench(tmp_path / "bench")
    with pytest.raises(ValueError, match="no complete pair 'nope'"):
        variant_strip(runs_of(bench), "nope", tmp_path / "x.png")
    with pytest.raises(ValueError, match=r"no run folder for \['v2_markers'\]"):
        runs_of(bench, ["v2_markers"])
    with pytest.raises(ValueError, match="no variant run folders"):
        runs_of(tmp_path / "empty")
    assert main([str(bench), "--pair", "nope", "--out", str(tmp_path / "y.png")]) == 2
    assert "error: " in capsys.readouterr().out
    assert main([str(bench), "--pair", SynthPair().pair_id, "--out", str(tmp_path / "z.png")]) == 0
    assert (tmp_path / "z.png").read_bytes()[:8] == PNG
