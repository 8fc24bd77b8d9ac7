"""The package layering of DESIGN.md, checked on the source: dependencies point one way.

    foundation (pilworld.types, .geometry, .kinematics) ← calib ← pilworld.config ← hw_drivers (contract, drivers)
        ← simrig (the simulated rig) ← hw_drivers.fakes (protocol fakes backed by it) ← rest of pilworld

The foundation is the data contract and the geometry every layer shares; it lives in ``pilworld``
(as the issues ask) but imports nothing from the layers above it, so ``calib`` and ``hw_drivers``
can use it without depending on the evaluation code.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FOUNDATION = ("pilworld.types", "pilworld.geometry", "pilworld.kinematics")
LAYERS: list[tuple[tuple[str, ...], tuple[str, ...]]] = [
    # (modules, what they may import from this project besides themselves and the foundation)
    (FOUNDATION, ()),
    (("calib",), ()),
    (("pilworld.config",), ("calib",)),
    # The simulated rig implements the Robot contract and its safety caps; nothing else of hw_drivers.
    (("simrig",), ("calib", "pilworld.config", "hw_drivers.robot", "hw_drivers.safety", "hw_drivers.errors")),
    # The protocol-level fakes are devices backed by the simulated rig.
    (("hw_drivers.fakes",), ("calib", "pilworld.config", "hw_drivers", "simrig")),
    (("hw_drivers",), ("calib", "pilworld.config")),
]


def _within(name: str, prefixes: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _project_imports(path: Path) -> set[str]:
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
    return {n for n in found if n.split(".")[0] in ("pilworld", "calib", "hw_drivers", "simrig") and n != "pilworld"}


def _sources() -> list[Path]:
    return sorted(p for pkg in ("pilworld", "calib", "hw_drivers", "simrig") for p in (ROOT / pkg).rglob("*.py"))


def _layer_of(path: Path) -> tuple[tuple[str, ...], tuple[str, ...]] | None:
    """The constrained layer a source file belongs to; None for the top layer (the rest of pilworld),
    which may import anything and so has nothing to check."""
    module = _module_name(path)
    return next(((own, allowed) for own, allowed in LAYERS if _within(module, own)), None)


CONSTRAINED = [p for p in _sources() if _layer_of(p) is not None]


def test_every_constrained_layer_has_sources() -> None:
    """A renamed package must not empty a layer silently (and with it this check)."""
    for own, _ in LAYERS:
        assert any(_within(_module_name(p), own) for p in CONSTRAINED), f"no sources found for layer {own}"


@pytest.mark.parametrize("path", CONSTRAINED, ids=lambda p: str(p.relative_to(ROOT)))
def test_imports_respect_layers(path: Path) -> None:
    layer = _layer_of(path)
    assert layer is not None
    own, allowed = layer
    ok = (*own, *FOUNDATION, *allowed)
    bad = sorted(n for n in _project_imports(path) if not _within(n, ok))
    assert not bad, f"{_module_name(path)} imports {bad}, outside its layer (allowed: {ok})"


def test_checker_sees_a_violation(tmp_path: Path) -> None:
    fake = tmp_path / "m.py"
    fake.write_text("from pilworld.control_video import ControlVideo\nimport calib.camera_model\n")
    assert _project_imports(fake) == {"pilworld.control_video", "calib.camera_model"}
