"""The simulated rig's own files are package data, named once (simrig.files)."""

from __future__ import annotations

import ast
import fnmatch
import tomllib
from pathlib import Path

from simrig.files import PACKAGE_DIR, SIM_RIG, SIM_RIG_IN_CHECKOUT, TASKS_DIR, resolve_rig

ROOT = Path(__file__).resolve().parents[2]
SOURCES = ("pilworld", "simrig", "calib", "hw_drivers", "scripts")


def test_the_rig_and_the_tasks_live_in_the_package_and_the_checkout_links_to_them() -> None:
    assert SIM_RIG.is_file() and not SIM_RIG.is_symlink()
    assert (ROOT / SIM_RIG_IN_CHECKOUT).resolve() == SIM_RIG
    assert (ROOT / "configs" / "tasks").resolve() == TASKS_DIR.resolve()
    assert sorted(TASKS_DIR.glob("*.yaml")), "no packaged task files"


def test_package_data_ships_every_file_the_defaults_need() -> None:
    """Installed without a checkout, the CLI's default rig and packaged tasks must be in the wheel."""
    globs = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["simrig"]
    needed = [SIM_RIG, *TASKS_DIR.rglob("*.*")]
    for path in needed:
        rel = path.relative_to(PACKAGE_DIR).as_posix()
        assert any(fnmatch.fnmatch(rel, g) and rel.count("/") == g.count("/") for g in globs), rel


def test_the_checkout_spelling_resolves_without_a_checkout(tmp_path: Path) -> None:
    assert resolve_rig(SIM_RIG_IN_CHECKOUT, tmp_path) == SIM_RIG  # an installed package: no configs/ beside it
    assert resolve_rig(SIM_RIG_IN_CHECKOUT, ROOT) == ROOT / SIM_RIG_IN_CHECKOUT
    assert resolve_rig("other/rig.yaml", tmp_path) == tmp_path / "other" / "rig.yaml"
    assert resolve_rig(SIM_RIG, tmp_path) == SIM_RIG


def _path_definitions(path: Path) -> list[int]:
    """Lines that spell the simulated rig's file as a path: a one-word string naming it, or ``… / "name"``."""
    name = SIM_RIG.name
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            text = node.value.strip()
            if text.endswith(name) and len(text.split()) == 1:
                found.append(node.lineno)
    return found


def test_one_definition_of_the_simulated_rig_path() -> None:
    where = {
        str(p.relative_to(ROOT)): lines
        for pkg in SOURCES
        for p in sorted((ROOT / pkg).rglob("*.py"))
        if (lines := _path_definitions(p))
    }
    assert set(where) == {"simrig/files.py"}, where
