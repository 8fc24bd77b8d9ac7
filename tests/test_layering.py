"""The package layering of DESIGN.md, checked on the source: dependencies point one way.

    foundation (pilworld.types, .geometry, .kinematics) ← calib ← pilworld.config ← hw_drivers (contract, drivers)
        ← simrig (the simulated rig) ← hw_drivers.fakes (protocol fakes backed by it) ← rest of pilworld

Above them, :data:`ORDER` ranks every package of the tree, top (the command line) to bottom; a module may
import its own package and any package ranked below it, never one above. No two packages import each
other and no two modules do (every import counts, deferred ones too; only ``if TYPE_CHECKING:`` blocks,
which never run, are left out).

The foundation is the data contract and the geometry every layer shares; it lives in ``pilworld``
(as the design asks) but imports nothing from the layers above it, so ``calib`` and ``hw_drivers``
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


# --- Task knowledge: a task is a file, read by the simulator and the scripted stand-in policies only.
# The world model and the automatic judges learn from recorded episodes; they may not read task files or the
# scripted policies' task knowledge. The hand-written reference judge of the paper's tasks (and v2's tracked
# objects, which reuse it) are the named exceptions until the learned judges and world model v3 replace them.
TASK_READERS = ("simrig", "pilworld.policies.scripted")
TASK_KNOWLEDGE = ("simrig.tasks", "pilworld.policies.scripted", "pilworld.reference.paper_tasks")
LEARNERS = ("pilworld.world_model", "pilworld.judges")
LEGACY_TASK_READERS = {
    "pilworld.reference.paper_tasks": "the hand-written reference judge of the paper's three tasks",
    "pilworld.judges.vision_success": "its success half (reads pilworld.reference.paper_tasks)",
    "pilworld.world_model.composite.objects": "v2's tracked objects (the paper tasks' shapes, from the reference)",
}


@pytest.mark.parametrize("path", _sources(), ids=lambda p: str(p.relative_to(ROOT)))
def test_only_the_simulator_and_scripted_policies_see_task_internals(path: Path) -> None:
    """Outside the simulator and the scripted policies, a task is reached through ``simrig.tasks``' public
    loader only (``load_task`` …), never through its submodules (schema, shapes, predicates)."""
    module = _module_name(path)
    if _within(module, TASK_READERS) or module in LEGACY_TASK_READERS:
        return
    inner = sorted(n for n in _project_imports(path) if n.startswith("simrig.tasks."))
    assert not inner, f"{module} imports task internals {inner}; use simrig.tasks.load_task"


@pytest.mark.parametrize(
    "path", [p for p in _sources() if _within(_module_name(p), LEARNERS)], ids=lambda p: str(p.relative_to(ROOT))
)
def test_world_model_and_judges_read_no_task_knowledge(path: Path) -> None:
    module = _module_name(path)
    if module in LEGACY_TASK_READERS:
        return
    bad = sorted(n for n in _project_imports(path) if _within(n, TASK_KNOWLEDGE))
    assert not bad, f"{module} reads task knowledge {bad}: the world model and the judges learn from episodes"


@pytest.mark.parametrize(
    "path",
    [p for p in _sources() if _within(_module_name(p), ("pilworld.world_model",))],
    ids=lambda p: str(p.relative_to(ROOT)),
)
def test_the_world_model_imports_nothing_from_the_judges(path: Path) -> None:
    """The imagined branch and the judge that scores it must not share perception and fail together unseen."""
    bad = sorted(n for n in _project_imports(path) if _within(n, ("pilworld.judges",)))
    assert not bad, f"{_module_name(path)} imports {bad}: shared image code belongs in pilworld.perception"


def test_legacy_task_readers_exist() -> None:
    """An exception that no longer names a module must go (so the list only shrinks)."""
    modules = {_module_name(p) for p in _sources()}
    assert set(LEGACY_TASK_READERS) <= modules


# --- The whole tree, top to bottom (a package imports only itself and packages below it).
ORDER: tuple[str, ...] = (
    "pilworld.__main__",
    "pilworld.cli",
    "pilworld.bench",
    "pilworld.annotate",
    "pilworld.demo",
    "pilworld.imagine",
    "pilworld.paired",
    "pilworld.report",
    "pilworld.metrics",
    "pilworld.ppi",
    "pilworld.rollout",
    "pilworld.envs",
    "pilworld.world_model",
    "pilworld.judges",
    "pilworld.reference",
    "pilworld.collection",
    "pilworld.starts",
    "pilworld.policies",
    "pilworld.calibration",
    "pilworld.control_video",
    "hw_drivers.fakes",
    "simrig",
    "hw_drivers",
    "pilworld.data",
    "pilworld.io",
    "pilworld.perception",
    "pilworld.options",
    "pilworld.config",
    "calib",
    "pilworld.kinematics",
    "pilworld.geometry",
    "pilworld.types",
    "pilworld",  # the top package's own __init__ (its version)
)
MODULES = {_module_name(p): p for p in _sources()}


def package_of(module: str) -> str:
    """The entry of :data:`ORDER` a module belongs to: the longest that is it or contains it."""
    # "pilworld" ranks the top package's own __init__ only: a subpackage missing from ORDER must not hide there.
    owners = [p for p in ORDER if module == p or (p != "pilworld" and _within(module, (p,)))]
    assert owners, f"{module} belongs to no package of ORDER: add its package there"
    return max(owners, key=len)


def _runtime_imports(path: Path) -> set[str]:
    """The project modules ``path`` imports when it runs (``from pkg import sub`` names ``pkg.sub``)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skipped: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skipped.update(id(n) for n in ast.walk(node))
    found: set[str] = set()
    for node in ast.walk(tree):
        if id(node) in skipped:
            continue
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            for alias in node.names:
                sub = f"{node.module}.{alias.name}"
                found.add(sub if sub in MODULES else node.module)
    out = set()
    for name in found:
        while name and name not in MODULES:  # an attribute of a module: the module
            name = name.rpartition(".")[0]
        if name:
            out.add(name)
    return out - {_module_name(path)}


IMPORTS = {m: _runtime_imports(p) for m, p in MODULES.items()}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_every_package_is_ranked() -> None:
    for module in MODULES:
        package_of(module)


@pytest.mark.parametrize("module", sorted(MODULES))
def test_imports_point_down_the_order(module: str) -> None:
    own = ORDER.index(package_of(module))
    up = sorted(n for n in IMPORTS[module] if ORDER.index(package_of(n)) < own)
    assert not up, f"{module} ({package_of(module)}) imports {up}, ranked above it in ORDER"


def test_no_package_imports_another_that_imports_it() -> None:
    graph: dict[str, set[str]] = {}
    for module, names in IMPORTS.items():
        graph.setdefault(package_of(module), set()).update(package_of(n) for n in names)
    for package, names in graph.items():
        names.discard(package)
    assert _cycles(graph) == []


def test_no_module_imports_another_that_imports_it() -> None:
    assert _cycles(IMPORTS) == []


def test_the_cycle_finder_finds_a_cycle() -> None:
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
