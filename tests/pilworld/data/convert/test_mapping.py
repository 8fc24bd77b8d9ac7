"""The mapping config: YAML loading, validation errors naming file and field, camera selection."""

from __future__ import annotations

from pathlib import Path

import pytest

from pilworld.config import ConfigError
from pilworld.data.convert import ConvertMapping, default_view_name, load_mapping


def test_default_view_names() -> None:
    assert default_view_name("observation.images.cam_high") == "cam_high"
    assert default_view_name("observation.image") == "image"  # PushT
    assert default_view_name("cam_left_wrist") == "cam_left_wrist"  # ALOHA HDF5
    assert default_view_name("observation.images.head.rgb") == "head_rgb"


def test_load_yaml(tmp_path: Path) -> None:
    path = tmp_path / "map.yaml"
    path.write_text(
        "cameras:\n  cam_high: observation.images.top\n  observation.images.hand: wrist\n"
        "resize: [224, 224]\ntask: fold the towel\nfps: 30\naction_key: action.joints\n"
    )
    m = load_mapping(path)
    assert m.cameras == {"cam_high": "top", "observation.images.hand": "wrist"}  # prefix stripped from views
    assert m.resize == (224, 224) and m.task == "fold the towel" and m.fps == 30 and m.action_key == "action.joints"
    assert m.state_key is None and m.origin is None and m.color_order == "rgb"
    available = ["observation.images.cam_high", "observation.images.hand", "observation.images.other"]
    assert m.select_cameras(available, source="s") == {
        "observation.images.cam_high": "top",
        "observation.images.hand": "wrist",
    }
    assert ConvertMapping().select_cameras(available, source="s")["observation.images.other"] == "other"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("camras: {a: b}\n", r"map.yaml: field 'camras': Extra inputs are not permitted"),
        ("resize: [0, 64]\n", r"map.yaml: field 'resize': expected \[height, width\] in 1..8192, got \[0, 64\]"),
        ("resize: [64]\n", r"map.yaml: field 'resize"),
        ("cameras: {a: top, b: top}\n", r"map.yaml: field 'cameras': view name 'top' is used for more than one camera"),
        ("cameras: {a: 'my view'}\n", r"field 'cameras': view name 'my view' \(for 'a'\) may only use letters"),
        ("cameras: {}\n", r"field 'cameras': needs at least one camera"),
        ("origin: simulated\n", r"field 'origin': Input should be 'real' or 'imagined'"),
        ("fps: 0\n", r"field 'fps': Input should be greater than 0"),
        ("task: '  '\n", r"field 'task': an instruction must not be empty"),
        ("- a\n", r"map.yaml: expected a mapping at the top level, got list"),
    ],
)
def test_errors_name_file_and_field(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "map.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_mapping(path)


def test_missing_file_and_overrides(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nope.yaml: config file not found"):
        load_mapping(tmp_path / "nope.yaml")
    m = ConvertMapping(resize=(64, 64)).with_overrides(task="stack", fps=None)
    assert m.task == "stack" and m.resize == (64, 64) and m.fps is None
    with pytest.raises(ConfigError, match=r"command line: field 'task': an instruction must not be empty"):
        m.with_overrides(task=" ")


def test_camera_selection_errors() -> None:
    with pytest.raises(ValueError, match=r"src: camera 'cam_x' not in the source \(available: \['a', 'b'\]\)"):
        ConvertMapping(cameras={"cam_x": "x"}).select_cameras(["b", "a"], source="src")
    with pytest.raises(ValueError, match=r"give the same view names \['top'\]; map them"):
        ConvertMapping().select_cameras(["observation.images.top", "top"], source="src")
