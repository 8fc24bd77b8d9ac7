"""Task files (docs/tasks.md): every packaged file validates, the paper tasks lay out the same for a seed,
and a bad file gives one line per problem naming the file, the field and what is allowed — never a
traceback, and nothing written anywhere."""

from __future__ import annotations

import copy
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from simrig.tasks import (
    PAPER_TASKS,
    TASKS_DIR,
    TaskFileError,
    check_task_file,
    load_task,
    packaged_tasks,
)
from simrig.tasks.mesh import MAX_EXTENT, load_mesh_parts

# ---------------------------------------------------------------------- packaged files


@pytest.mark.parametrize("name", packaged_tasks())
def test_every_packaged_task_file_validates(name: str) -> None:
    assert check_task_file(name) == []
    task = load_task(name)
    assert task.simulated and task.name == name and task.num_subtasks >= 1
    for seed in range(5):  # every object laid out on the table, within the arms' reach
        for obj, pose in task.layout(seed).poses.items():
            x, y, _ = pose.xyz
            assert -0.2 <= x <= 0.25 and -0.3 <= y <= 0.3, f"{name}: {obj} starts at {pose.xyz}"


def test_packaged_instructions_are_unique() -> None:
    """The scripted policies recognise a packaged task by its instruction."""
    instructions = [load_task(n).instruction.strip().lower() for n in packaged_tasks()]
    assert len(set(instructions)) == len(instructions)


def test_packaged_meshes_are_closed_and_small() -> None:
    meshes = sorted((TASKS_DIR / "meshes").glob("*.*"))
    assert meshes, "the packaged tasks include a mesh object"
    for path in meshes:
        parts = load_mesh_parts(str(path))  # raises MeshError for an open or oversized mesh
        lo, hi = np.array(parts.bounds[0]), np.array(parts.bounds[1])
        assert float(np.max(hi - lo)) <= MAX_EXTENT


# Seed 0 of each paper task: object centres (x, y) [m]. The layouts are the paper's; they must not drift.
PAPER_SEED0 = {
    "sort_cubes": {
        "cube_small": (-0.045352, -0.195388),
        "cube_medium": (0.033257, -0.044732),
        "cube_large": (-0.111923, 0.220558),
    },
    "stack_bowls": {
        "bowl_large": (-0.037958, -0.208166),
        "bowl_medium": (0.038358, 0.180714),
        "bowl_small": (-0.06862, 0.08626),
    },
    "stack_blocks": {
        "block_red": (0.113933, -0.157113),
        "block_sky": (-0.087803, 0.214893),
        "block_green": (-0.004315, 0.000112),
    },
}


@pytest.mark.parametrize("name", PAPER_TASKS)
def test_paper_layouts_are_deterministic_per_seed(name: str, tmp_path: Path) -> None:
    task = load_task(name)
    fresh = load_task(shutil.copy(TASKS_DIR / f"{name}.yaml", tmp_path / f"{name}.yaml"))  # loaded anew
    assert fresh is not task and fresh.digest == task.digest
    for seed in range(6):
        a, b = task.layout(seed), fresh.layout(seed)
        assert a.poses == b.poses and a.goals == b.goals, f"{name}: seed {seed} differs between loads"
        assert task.layout(seed).poses == a.poses  # and between calls
    assert task.layout(0).poses != task.layout(1).poses
    got = {n: p.xyz[:2] for n, p in task.layout(0).poses.items()}
    for obj, xy in PAPER_SEED0[name].items():
        np.testing.assert_allclose(got[obj], xy, atol=1e-6, err_msg=f"{name}: {obj} at seed 0")


# ---------------------------------------------------------------------- hardware-only files


def test_a_hardware_only_task_file_loads(tmp_path: Path) -> None:
    path = tmp_path / "fold_towel.yaml"
    path.write_text(
        "# A task for a hardware rig only: no objects, the operator sets up and judges each subtask.\n"
        "name: fold_towel\n"
        'instruction: "fold the towel in half."\n'
        "subtasks:\n"
        "  - operator_setup: a towel lies flat and unfolded in front of the robot\n"
        "    operator_success: the towel is folded once, edges within 3 cm of each other\n"
        "  - operator_setup: the towel, folded once\n"
        "    operator_success: the towel is folded twice and lies inside the tape square\n",
        encoding="utf-8",
    )
    assert check_task_file(path) == []
    task = load_task(path)
    assert task.simulated is False and task.num_subtasks == 2 and task.object_names == ()
    assert task.subtask(1).operator_success.startswith("the towel is folded twice")
    with pytest.raises(ValueError, match="hardware-only"):
        task.layout(0)


# ---------------------------------------------------------------------- bad files

BASE: dict[str, Any] = {
    "name": "block_in_cup",
    "instruction": "put the block in the cup.",
    "objects": [
        {"name": "block", "shape": "box", "size": [0.04, 0.04, 0.04], "mass": 0.05, "colour": [0.9, 0.2, 0.2]},
        {"name": "cup", "shape": "cup", "radius": 0.05, "height": 0.05, "mass": 0.1, "colour": [0.1, 0.6, 0.9]},
    ],
    "regions": [{"name": "mark", "centre": [0.15, 0.0], "radius": 0.02}],
    "layout": {"scatter": [{"objects": ["block", "cup"], "x": [-0.1, 0.1], "y": [-0.2, 0.2], "min_distance": 0.12}]},
    "subtasks": [{"object": "block", "goal": {"all": [{"inside": "cup"}, {"upright": None}]}}],
}
RED = [0.9, 0.2, 0.2]


def _set(path: str, value: Any) -> Callable[[dict[str, Any]], None]:
    """A change of ``BASE`` at ``path`` (dotted; list indices as numbers); ``value`` DELETE removes the key."""

    def apply(data: dict[str, Any]) -> None:
        *head, last = path.split(".")
        node: Any = data
        for key in head:
            node = node[int(key)] if isinstance(node, list) else node[key]
        key_: Any = int(last) if isinstance(node, list) else last
        if value is DELETE:
            del node[key_]
        else:
            node[key_] = value

    return apply


DELETE = object()


def _mesh(file: str) -> dict[str, Any]:
    return {"name": "block", "shape": "mesh", "file": file, "mass": 0.05, "colour": RED}


def _rename_top(old: str, new: str) -> Callable[[dict[str, Any]], None]:
    def apply(data: dict[str, Any]) -> None:
        data[new] = data.pop(old)

    return apply


# (kind, change of BASE or the file's text, the field the first line names, a phrase saying what is allowed)
BAD: list[tuple[str, Callable[[dict[str, Any]], None] | str, str, str]] = [
    ("unknown shape", _set("objects.0.shape", "pyramid"), "objects.0.shape", "allowed: box, cylinder"),
    ("negative size", _set("objects.0.size", [-0.04, 0.04, 0.04]), "objects.0.size.0", "greater than 0"),
    ("zero radius", _set("objects.1.radius", 0), "objects.1.radius", "greater than 0"),
    ("too heavy", _set("objects.0.mass", 50), "objects.0.mass", "less than or equal to 5"),
    ("missing mass", _set("objects.0.mass", DELETE), "objects.0.mass", "required"),
    (
        "goal names a missing object",
        _set("subtasks.0.goal", {"on": "ghost"}),
        "subtasks.0.goal.on.support",
        "objects: block, cup",
    ),
    ("subtask names a missing object", _set("subtasks.0.object", "ghost"), "subtasks.0.object", "objects: block, cup"),
    (
        "goal names a missing region",
        _set("subtasks.0.goal", {"in_region": "nowhere"}),
        "subtasks.0.goal.in_region.region",
        "regions: mark",
    ),
    (
        "layout cannot be satisfied",
        _set(
            "layout.scatter.0", {"objects": ["block", "cup"], "x": [0.0, 0.05], "y": [0.0, 0.05], "min_distance": 0.2}
        ),
        "layout.scatter.0",
        "widen the area or lower min_distance",
    ),
    ("object placed by no scatter group", _set("layout.scatter.0.objects", ["block"]), "layout", "cup placed by no"),
    (
        "starts inside something that is not a container",
        lambda d: d["layout"].update(
            scatter=[{**d["layout"]["scatter"][0], "objects": ["block"]}],
            stacked=[{"object": "cup", "inside": "block"}],
        ),
        "layout.stacked.0.inside",
        "not a container (bowl, cup or open_box)",
    ),
    ("scatter area off the table", _set("layout.scatter.0.x", [-0.1, 0.9]), "layout.scatter.0.x", "x in [-0.6, 0.5]"),
    (
        "missing texture file",
        _set("objects.0.texture", {"image": "nope.png"}),
        "objects.0.texture.image",
        "texture image not found",
    ),
    (
        "texture with neither image nor pattern",
        _set("objects.0.texture", {"scale": 0.02}),
        "objects.0.texture",
        "exactly one of 'image'",
    ),
    (
        "unknown texture pattern",
        _set("objects.0.texture", {"pattern": "paisley"}),
        "objects.0.texture.pattern",
        "'checker', 'stripes', 'dots', 'noise' or 'wood'",
    ),
    ("missing mesh file", _set("objects.0", _mesh("nope.obj")), "objects.0.file", "mesh file not found"),
    ("mesh not an OBJ or STL", _set("objects.0", _mesh("block.ply")), "objects.0.file", "OBJ or STL"),
    ("mesh not closed", _set("objects.0", _mesh("open.obj")), "objects.0.file", "must be a closed surface"),
    ("mesh too large", _set("objects.0", _mesh("big.obj")), "objects.0.file", "at most 0.3 m"),
    ("subtask without a goal", _set("subtasks.0.goal", DELETE), "subtasks.0.goal", "a predicate: all, any"),
    ("duplicate object names", _set("objects.1.name", "block"), "objects.1.name", "must be unique"),
    (
        "unknown predicate",
        _set("subtasks.0.goal", {"near": "cup"}),
        "subtasks.0.goal",
        "allowed: all, any, in_region, on, inside, upright, on_table",
    ),
    (
        "two predicates in one goal",
        _set("subtasks.0.goal", {"inside": "cup", "upright": None}),
        "subtasks.0.goal",
        "exactly one predicate",
    ),
    (
        "inside something that is not a container",
        _set("subtasks.0", {"object": "cup", "goal": {"inside": "block"}}),
        "subtasks.0.goal.inside.container",
        "not a container (bowl, cup or open_box)",
    ),
    (
        "container too small for its content",
        _set("objects.1.radius", 0.02),
        "subtasks.0.goal.all.0.inside.container",
        "too small for block",
    ),
    (
        "object too wide for the gripper",
        _set("objects.0.size", [0.09, 0.09, 0.03]),
        "objects.0.size",
        "the gripper holds at most 75 mm",
    ),
    ("region off the table", _set("regions.0.centre", [0.9, 0.0]), "regions.0.centre", "off the table (x in"),
    (
        "colour out of range",
        _set("objects.0.colour", [1.2, 0.0, 0.0]),
        "objects.0.colour",
        "values in 0..1 or a hex string",
    ),
    ("colour not hex", _set("objects.0.colour", "#zz0000"), "objects.0.colour", "values in 0..1 or a hex string"),
    ("no colour and no texture", _set("objects.0.colour", DELETE), "objects.0", "give a 'colour' or a 'texture'"),
    (
        "hardware-only task whose subtask names a goal",
        'name: fold_towel\ninstruction: "fold it."\nsubtasks:\n  - {operator_setup: a towel, goal: {upright: null}}\n',
        "subtasks.0.goal",
        "operator_setup and operator_success",
    ),
    ("unknown top-level key (typo)", _rename_top("subtasks", "subtask"), "subtask", "did you mean 'subtasks'?"),
    ("unknown object key (typo)", _set("objects.0.colur", RED), "objects.0.colur", "did you mean 'colour'?"),
    ("bad task name", _set("name", "Block In Cup"), "name", "lower-case letters, digits and '_'"),
    ("blank instruction", _set("instruction", "   "), "instruction", "must not be blank"),
    ("no subtasks", _set("subtasks", []), "subtasks", "at least 1 item"),
    (
        "bowl wider at the bottom than the top",
        _set(
            "objects.1",
            {
                "name": "cup",
                "shape": "bowl",
                "bottom_radius": 0.06,
                "top_radius": 0.05,
                "height": 0.04,
                "mass": 0.1,
                "colour": [0.1, 0.6, 0.9],
            },
        ),
        "objects.1",
        "must exceed bottom_radius",
    ),
    ("non-YAML garbage", "{{{ ::: [\n- nope: [", "", "not valid YAML at line 1"),
    ("a list, not a mapping", "- name: x\n- instruction: y\n", "", "expected a mapping (name, instruction"),
    ("an empty file", "", "", "the file is empty"),
]


def _listing(*roots: Path) -> dict[str, float]:
    return {str(p): p.stat().st_mtime for root in roots for p in root.rglob("*")}


@pytest.fixture(scope="module")
def mesh_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    import trimesh

    folder = tmp_path_factory.mktemp("meshes")
    box = trimesh.creation.box((0.04, 0.04, 0.04))
    box.export(folder / "block.ply")
    trimesh.creation.box((0.5, 0.04, 0.04)).export(folder / "big.obj")
    open_box = trimesh.creation.box((0.04, 0.04, 0.04))
    open_box.faces = open_box.faces[:-2]  # one side missing
    open_box.export(folder / "open.obj")
    return folder


def test_the_base_of_the_bad_files_is_valid(tmp_path: Path) -> None:
    path = tmp_path / "base.yaml"
    path.write_text(yaml.safe_dump(BASE, sort_keys=False), encoding="utf-8")
    assert check_task_file(path) == []


@pytest.mark.parametrize(("kind", "change", "field", "allowed"), BAD, ids=[b[0] for b in BAD])
def test_a_bad_task_file_names_the_file_the_field_and_what_is_allowed(
    kind: str,
    change: Callable[[dict[str, Any]], None] | str,
    field: str,
    allowed: str,
    mesh_dir: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    if isinstance(change, str):
        text = change
    else:
        data = copy.deepcopy(BASE)
        change(data)
        text = yaml.safe_dump(data, sort_keys=False)
    path = mesh_dir / "bad.yaml"  # next to the meshes it may name
    path.write_text(text, encoding="utf-8")
    monkeypatch.chdir(mesh_dir)
    before = _listing(mesh_dir, TASKS_DIR)
    problems = check_task_file(path)
    assert problems, f"{kind}: no problem found"
    first = problems[0]
    assert "\n" not in first and all("\n" not in p for p in problems)
    assert "Traceback" not in first and "Input should" not in first
    prefix = f"{path}: field '{field}': " if field else f"{path}: "
    assert first.startswith(prefix), f"{kind}: {first}"
    assert allowed in first, f"{kind}: {first}"
    with pytest.raises(TaskFileError) as info:
        load_task(path)
    assert str(info.value).splitlines()[0].startswith(first)
    assert info.value.problems == problems
    assert _listing(mesh_dir, TASKS_DIR) == before, f"{kind}: checking the file wrote something"


def test_a_missing_task_file_and_an_unknown_name_are_one_line(tmp_path: Path) -> None:
    (missing,) = check_task_file(tmp_path / "nope.yaml")
    assert missing == f"{tmp_path / 'nope.yaml'}: task file not found"
    (unknown,) = check_task_file("no_such_task")
    assert unknown.startswith("task: no packaged task called 'no_such_task' (packaged: ")
    assert "sort_cubes" in unknown


def test_every_problem_is_listed_and_the_error_says_how_many(mesh_dir: Path) -> None:
    data = copy.deepcopy(BASE)
    data["objects"][0]["colur"] = RED
    data["objects"][1]["radius"] = -1
    data["regions"][0]["radius"] = 0
    path = mesh_dir / "many.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    problems = check_task_file(path)
    fields = [p.split("field '")[1].split("'")[0] for p in problems]
    assert fields == ["objects.0.colur", "objects.1.radius", "regions.0.radius"]
    with pytest.raises(TaskFileError, match=r"\(and 2 more problem\(s\): pilworld task check FILE lists them\)"):
        load_task(path)


def test_object_textures_repeat_every_scale_metres() -> None:
    """MuJoCo wraps a cube texture once per face (texrepeat is ignored): the image itself holds the periods."""
    import cv2

    from simrig.tasks.textures import SIZE, tiles

    task = load_task("mug_on_coaster")
    (mug,) = (o for o in task.objects() if o.name == "mug")
    files = dict(mug.assets.files)
    image = cv2.imdecode(np.frombuffer(files["tex_mug.png"], np.uint8), cv2.IMREAD_COLOR)
    g = task.geometry["mug"]
    texture = task.spec.objects[0].texture
    assert texture is not None
    n = tiles(max(2 * g.radius, g.height), texture.scale)
    assert n > 1 and image.shape[:2] == (SIZE * n, SIZE * n)
    assert all("texrepeat" not in line for line in mug.assets.xml if line.startswith("<material"))


@pytest.mark.parametrize("name", packaged_tasks())
def test_packaged_objects_can_be_told_apart_by_hue(name: str) -> None:
    """The scripted checkpoints find objects by hue (docs/tasks.md, "Colours and the scripted checkpoints")."""
    from pilworld.perception.colour import ColourClass

    task = load_task(name)
    classes = [ColourClass(n, task.colour(n)) for n in task.object_names]
    assert all(c.saturation >= 0.5 for c in classes), [(c.name, c.saturation) for c in classes]
    for i, a in enumerate(classes):
        for b in classes[i + 1 :]:
            gap = abs(a.hue_deg - b.hue_deg) % 360
            assert min(gap, 360 - gap) >= 25, f"{name}: {a.name} and {b.name} are {gap:.0f}° apart in hue"
