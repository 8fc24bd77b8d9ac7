"""``python -m pilworld.bench.results_tables``: RESULTS.md's tables from the benches' JSON files."""

from __future__ import annotations

from pathlib import Path

import pytest

from pilworld.bench.results_tables import main


def test_missing_empty_and_broken_results_are_named_not_raised(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A bench still running leaves its JSON empty, a failed one a log line: each is reported and skipped."""
    (tmp_path / "paired-full.json").write_text("")
    (tmp_path / "speed-accuracy-full.json").write_text("Traceback (most recent call last):\n")
    assert main([str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert f"({tmp_path / 'paired-full.json'} is not a bench result" in out
    assert f"({tmp_path / 'speed-accuracy-full.json'} is not a bench result" in out
    assert f"({tmp_path / 'stability-full.json'} missing)" in out


def _variant(label: str, sr_imag: float, agree_s: tuple[int, int], agree_f: tuple[int, int]) -> dict[str, object]:
    def block(k: int, n: int) -> dict[str, object]:
        return {"k": k, "n": n, "share": k / n if n else None, "ci95": [0.1, 0.9] if n else None}

    overall = {
        "sr_real": 0.5,
        "sr_imag": sr_imag,
        "abs_delta_sr": abs(sr_imag - 0.5),
        "hfr": 0.9,
        "sr_real_checker": 0.48,
        "pearson": 0.9,
        "spearman": None,
        "mmrv": 0.05,
        "n_subtasks": 4,
        "ci95": {"sr_imag": [0.2, 0.8], "abs_delta_sr": [0.0, 0.3], "hfr": [0.85, 0.95], "sr_real": [0.2, 0.8]},
        "ranking_ci95": {"pearson": [0.5, 1.0]},
    }
    agreement = {"successes": block(*agree_s), "failures": block(*agree_f), "all": block(3, 4)}
    agreement["tasks"] = {"sort_cubes": {"successes": block(*agree_s), "failures": block(*agree_f)}}
    head = {"psnr_pooled": 24.5, "gain_over_frozen_pooled_db": 3.2, "ssim": 0.91}
    return {
        "label": label,
        "overall": overall,
        "tasks": {"sort_cubes": {"sr_real": 0.5, "sr_imag": sr_imag, "abs_delta_sr": 0.0, "hfr": 0.9}},
        "single_step": {"per_view": {"cam_high": head}},
        "agreement": agreement,
    }


def test_paired_tables_print_the_rows_the_gamma_plus_ablation_and_the_claims() -> None:
    from pilworld.bench.results_tables import paired_tables

    r = {
        "variants": {
            "pilworld": _variant("shipped", 0.5, (2, 2), (2, 2)),
            "v2_markers": _variant("markers", 0.25, (1, 2), (2, 2)),
            "v2_no_history": _variant("no history", 0.75, (2, 2), (1, 2)),
        },
        "gamma_plus_rows": ["v2_markers", "pilworld"],
        "gamma_plus_steps": [
            {
                "from": "v2_markers",
                "to": "pilworld",
                "difference": {"abs_delta_sr": -0.1, "hfr": 0.5, "agreement": 0.05},
                "ci95": {"abs_delta_sr": [-0.2, 0.0], "hfr": [0.4, 0.6], "agreement": [-0.05, 0.1]},
                "direction": {"abs_delta_sr": "not separated", "hfr": "holds", "agreement": "not separated"},
            }
        ],
        "claims": [
            {
                "claim": "history",
                "text": "the history memory matters",
                "better": "pilworld",
                "worse": "v2_no_history",
                "difference": {"abs_delta_sr": -0.25, "hfr": 0.0, "agreement": 0.25},
                "ci95": {"abs_delta_sr": [-0.5, -0.05], "hfr": [0.0, 0.0], "agreement": [0.0, 0.5]},
                "direction": {"abs_delta_sr": "holds", "hfr": "not separated", "agreement": "not separated"},
            }
        ],
    }
    text = paired_tables(r)
    assert "SR_real (shared real branches): 50.0 [20.0, 80.0] %" in text
    assert "| v2_markers: markers | 25.0 [20.0, 80.0] | 25.0 [0.0, 30.0] |" in text
    assert "1/2 = 0.50 [0.10, 0.90]" in text and "2/2 = 1.00 [0.10, 0.90]" in text
    assert "The Γ⁺ ablation" in text and "| v2_markers | 25.0" in text and "| 24.50 |" in text
    assert "| the history memory matters | pilworld − v2_no_history | -25.0 [-50.0, -5.0] |" in text
    assert "holds · not separated · not separated" in text
    assert "| v2_markers → pilworld | -10.0 [-20.0, 0.0] | 0.500 [0.400, 0.600] |" in text
    assert "not separated · holds · not separated |" in text
    assert "| v2_no_history | sort_cubes | 50.0 | 75.0 |" in text
    # Without the new keys (a result of an older bench), the tables still print.
    old = {"variants": {"pilworld": {k: v for k, v in r["variants"]["pilworld"].items() if k != "agreement"}}}
    assert "| pilworld: shipped |" in paired_tables(old)
