"""The live view selector and collection loop, on synthetic board images (no camera, no simulator)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from calib.board import ChArUcoBoard
from calib.camera_model import CameraModel
from calib.detect import BoardDetector, Detection
from calib.synthetic import synthetic_views
from pilworld.calibration.live_intrinsics import (
    LiveTargets,
    ViewSelector,
    collect_live,
    coverage_lines,
    load_views,
    status_lines,
    write_preview,
)

BOARD = ChArUcoBoard.from_yaml(Path(__file__).resolve().parents[3] / "configs" / "board" / "charuco_7x5_a4.yaml")
W = H = 480
K = np.array([[560.0, 0.0, 239.5], [0.0, 560.0, 239.5], [0.0, 0.0, 1.0]])
CAMERA = CameraModel(K=K, dist=np.zeros(0), T_cam_base=np.eye(4), width=W, height=H, name="cam_high")


@pytest.fixture(scope="module")
def views() -> list[tuple[np.ndarray, Detection]]:
    detector = BoardDetector(BOARD)
    out = []
    for i, v in enumerate(synthetic_views(BOARD, CAMERA, 24, seed=3)):
        out.append((v.image, detector.detect(v.image, name=f"{i:03d}.png")))
    return out


def selector(**targets: float) -> ViewSelector:
    guess = K.copy()
    guess[0, 0] = guess[1, 1] = 500.0  # a rough first guess, as from a rig's designed camera
    return ViewSelector((W, H), guess, LiveTargets(**targets))  # type: ignore[arg-type]


def test_targets_are_validated() -> None:
    with pytest.raises(ValueError, match="coverage target"):
        LiveTargets(coverage=1.5)
    with pytest.raises(ValueError, match="at least 4 views"):
        LiveTargets(views=3)
    with pytest.raises(ValueError, match="max views"):
        LiveTargets(views=20, max_views=10)
    with pytest.raises(ValueError, match="RMS target"):
        LiveTargets(rms_px=0.0)


def test_keeps_new_views_refuses_duplicates_and_sparse_frames(views: list[tuple[np.ndarray, Detection]]) -> None:
    sel = selector()
    _, first = views[0]
    assert sel.offer(first).kept and "coverage" in sel.offer(views[1][1]).reason
    again = sel.offer(first)  # the board held still: the same corners again
    assert not again.kept and again.reason == "near-duplicate of view 0"
    sparse = Detection("x", (W, H), first.corner_ids[:5], first.corners[:5], first.marker_ids, False, BOARD)
    assert sel.offer(sparse).reason == "5 corners (< 12)"
    assert len(sel.views) == 2 and sel.rms_px is None  # no solve before 4 views
    with pytest.raises(ValueError, match="frame size"):
        sel.offer(Detection("y", (W * 2, H), first.corner_ids, first.corners, first.marker_ids, False, BOARD))


def test_running_solve_converges_and_targets_say_what_is_missing(views: list[tuple[np.ndarray, Detection]]) -> None:
    sel = selector(views=8, coverage=0.5, tilted_views=2)
    assert any(m.startswith("views 0/8") for m in sel.missing())
    for _, det in views:
        sel.offer(det)
    assert len(sel.views) >= 8 and sel.rms_px is not None and sel.rms_px < 0.5
    assert sel.K is not None and abs(sel.K[0, 0] - 560.0) / 560.0 < 0.02  # tilts use the solved camera
    assert sel.coverage >= 0.5 and sel.tilted >= 2 and sel.missing() == []
    assert len(coverage_lines(sel)) == 6 and all(len(r.split()) == 8 for r in coverage_lines(sel))
    lines = status_lines(sel, 12.0, "kept: adds coverage (+1 cell)")
    assert lines[1] == "targets reached" and lines[-1].startswith("last frame: kept")


def test_max_views_caps_the_selection(views: list[tuple[np.ndarray, Detection]]) -> None:
    sel = selector(views=4, max_views=5, coverage=1.0)
    for _, det in views:
        sel.offer(det)
    assert len(sel.views) == 5 and sel.offer(views[-1][1]).reason == "5 views kept already"


def test_collect_live_saves_each_kept_view_and_resumes(
    views: list[tuple[np.ndarray, Detection]], tmp_path: Path
) -> None:
    frames = iter([(img, i) for i, (img, _) in enumerate(views)] * 2)
    shown: list[list[str]] = []
    sel = selector(views=6, coverage=0.4, tilted_views=1, max_views=40)
    detector = BoardDetector(BOARD)
    result = collect_live(
        lambda: next(frames), sel, detector, tmp_path / "v", show=shown.append, preview=tmp_path / "p.png"
    )
    assert result.stop == "targets reached" and len(result.views) == len(sel.views) >= 6
    assert [p.name for p in result.views] == [f"{i:03d}.png" for i in range(len(result.views))]
    assert (tmp_path / "p.png").is_file() and shown and shown[-1][1] == "targets reached"
    # A resumed collection re-detects the saved views and numbers new ones after them.
    earlier = load_views(tmp_path / "v", detector)
    assert [name for name, _, _ in earlier] == [p.name for p in result.views]
    assert all(d.n_corners >= 12 for _, _, d in earlier)


def test_collect_live_stops_on_request_and_on_a_camera_fault(
    views: list[tuple[np.ndarray, Detection]], tmp_path: Path
) -> None:
    sel = selector()
    count = {"n": 0}

    def grab() -> tuple[np.ndarray, int]:
        count["n"] += 1
        if count["n"] > 3:
            raise TimeoutError("cam_high: no frame for 2.0 s")
        return views[count["n"]][0], count["n"]

    with pytest.raises(TimeoutError, match="no frame"):
        collect_live(grab, sel, BoardDetector(BOARD), tmp_path / "v")
    assert len(list((tmp_path / "v").glob("*.png"))) == 3  # every view kept before the fault is on disk
    sel2 = selector()
    result = collect_live(grab, sel2, BoardDetector(BOARD), tmp_path / "w", stop_requested=lambda: "Enter")
    assert result.stop == "Enter" and result.views == ()


def test_preview_is_written_atomically(views: list[tuple[np.ndarray, Detection]], tmp_path: Path) -> None:
    sel = selector()
    img, det = views[0]
    sel.offer(det)
    write_preview(tmp_path / "p.png", img, sel, det)
    out = cv2.imread(str(tmp_path / "p.png"))
    assert out is not None and out.shape == (H, W, 3) and not list(tmp_path.glob("*.tmp.png"))
