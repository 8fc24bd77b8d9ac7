"""The one printer of ``pilworld bench``: tables align header and rows; ``--json`` puts the result last."""

from __future__ import annotations

import argparse
import json

import pytest

from pilworld.bench.output import Column, emit, num, pct, table
from pilworld.bench.paired import PAIRED_COLUMNS
from pilworld.bench.ppi import PPI_COLUMNS


def test_table_aligns_every_row_under_its_header() -> None:
    cols = (Column("name", 6, "name", align="<"), Column("rate", 7, "rate", pct), Column("x", 6, "x", num))
    lines = table(cols, [{"name": "a", "rate": 0.5, "x": 1.234}, {"name": "longer", "rate": None, "x": None}])
    assert lines == ["  name     rate     x", "  a        50.0  1.23", "  longer      —     —"]


def test_paired_table_reads_the_bench_rows() -> None:
    row = {"variant": "pilworld", "sr_real": 0.537, "sr_imag": 0.003, "abs_delta_sr": 0.534, "hfr": 0.46,
           "pearson": None, "mmrv": 0.1, "head": {"psnr_pooled": 27.456}}  # fmt: skip
    header, line = table(PAIRED_COLUMNS, [row])
    assert header.split() == ["variant", "SR_real", "SR_imag", "|ΔSR|", "HFR", "Pearson", "MMRV", "head", "PSNR"]
    assert line.split() == ["pilworld", "53.7", "0.3", "53.4", "0.46", "—", "0.10", "27.46"]


def test_ppi_table_has_a_cell_per_column() -> None:
    s = {"method": "ppi++", "predictor": "imagined", "n": 10, "N": 300, "coverage_ppi": 0.95}
    s |= {"coverage_classical": 0.948, "width_ratio": None, "width_ratio_formula": 0.7, "ess_gain_measured": 2.0}
    _, line = table(PPI_COLUMNS, [s], indent="")
    assert line.split() == ["ppi++", "imagined", "10", "300", "0.950", "0.948", "—", "0.700", "2.00"]


@pytest.mark.parametrize("as_json", [False, True])
def test_emit_prints_lines_then_the_result_last(capsys: pytest.CaptureFixture[str], as_json: bool) -> None:
    assert emit(argparse.Namespace(json=as_json), {"a": 1}, ["first", "second"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[:2] == ["first", "second"]
    assert (json.loads(out[-1]) == {"a": 1}) if as_json else len(out) == 2
