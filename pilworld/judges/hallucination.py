"""The automatic hallucination detector (docs/judges.md): the first frame of an obvious hallucination, and why.

The paper's annotators mark the first frame of "object disappearance or sudden appearance, cross-view
spatial conflict, discontinuous arm or object motion" (appendix, "Hallucination-free ratio"). This
judge looks for each of those with its own check (``hallucination_checks.py``) and reports the
earliest; ties go to the category listed first in :data:`CATEGORIES`:

* **cross-view conflict** — a view stops being the camera it is: the head view's static background
  changes all at once, or a wrist view stops showing its own gripper, or the head view starts to;
* **discontinuous arm motion** — the head view does not show an arm where the state's forward
  kinematics projects it (or shows one where none is), e.g. a gripper far from its FK projection;
* **object disappearing / appearing / discontinuous object motion** — an object's colour blob
  vanishes, appears (out of nothing, or as a duplicate) or jumps, and no arm explains it: not
  hidden behind or revealed from behind an arm or another object, not carried by a gripper (the
  blob, moved with the gripper's projected TCP, is hidden or seen there), not at the image border.

Each unexplained change must still be there one frame later; the reported frame is where it first
showed. It needs the state (the measured joints in the real branch, the commanded stride-aligned
actions in the imagined one) and the rig's head camera and kinematics. The objects' colours are found in
the episode itself (:func:`pilworld.perception.objects.discover_colours_over`: saturated hues forming
compact blobs, away from the predicted arms, in every frame since an arm often hides an object for all
but a few frames), so no task knowledge is read; a scene without coloured objects gets
only the arm and view checks. Measured detection and false-positive rates: ``pilworld bench hallucination``
(``pilworld/bench/hallucination.py``) and docs/judges.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pilworld.config.rig import RigConfig
from pilworld.data.episode import Episode
from pilworld.data.outcomes import JudgeKind
from pilworld.judges.base import JudgeContext, Verdict
from pilworld.judges.hallucination_checks import (
    CATEGORIES,
    Finding,
    HeadScene,
    Thresholds,
    arm_visibility,
    check_arms,
    check_objects,
    check_views,
)
from pilworld.judges.hallucination_ego import check_wrist_motion
from pilworld.judges.hallucination_scene import (
    REFERENCE_WIDTH,
    ArmShape,
    background_table,
    colourful_mask,
    dilate,
    empty_pixels,
    learn_background,
    learn_table,
    object_labels,
    predict_arms,
    ratio_chroma,
    shadow_like,
    shadow_tint,
    smooth,
    table_mask,
    without_table_texture,
)
from pilworld.judges.hallucination_wrist import check_wrist_objects
from pilworld.perception.objects import discover_colours_over
from pilworld.types import HEAD_VIEW

__all__ = ["CATEGORIES", "HallucinationDetector", "find_hallucinations", "head_scene"]


def head_scene(
    episode: Episode, rig: RigConfig, task: str, thresholds: Thresholds | None = None, shape: ArmShape | None = None
) -> HeadScene:
    """What the checks need from the head view of ``episode`` (see ``hallucination_scene.py``)."""
    if HEAD_VIEW not in episode.images:
        raise ValueError(f"episode: the detector needs the head view {HEAD_VIEW!r}, got {sorted(episode.images)}")
    images = episode.images[HEAD_VIEW]
    cam = rig.head_camera_model
    if images.shape[1:3] != (cam.height, cam.width):
        raise ValueError(
            f"episode: {HEAD_VIEW} frames are {images.shape[2]}x{images.shape[1]} but the rig's head camera is "
            f"{cam.width}x{cam.height}"
        )
    arms = predict_arms(rig, episode.state, shape)
    # The objects' colours, found in every frame away from the predicted arms (an arm often hides an object
    # for all but a few frames; one missed colour is one object never tracked): no task knowledge.
    classes = discover_colours_over(images, exclude=np.stack([dilate(a, 2) for a in arms.whole]), samples=len(images))
    th = thresholds or Thresholds()
    scale = cam.width / REFERENCE_WIDTH
    # A colour that is the table's own grain, not an object, is no object class (a wood table's warm specks).
    classes = without_table_texture(
        images,
        classes,
        arms.whole,
        frames=th.texture_frames,
        faded_saturation=th.faded_saturation,
        ratio=th.texture_ratio,
        specks=th.texture_specks,
        scale=scale,
    )
    labels = object_labels(images, classes, th.faded_saturation)
    colourful = colourful_mask(images)
    # The table's colour from the start frame (real in both branches), away from arms and objects: the
    # rule for pixels the empty scene below never shows.
    table = learn_table(images[0], dilate(arms.whole[0], 3) | dilate(labels[0] > 0, 2))
    # The empty scene, pixel by pixel, from the frames where nothing covers each pixel: a textured table,
    # its shading and a tinted light are explained where one table colour is not (the varied look).
    blurred = smooth(images, th.background_blur_px * scale)
    no_arm, empty = empty_pixels(arms.whole, (labels > 0) | colourful, th.background_margin_px * scale)
    background = learn_background(blurred, no_arm, empty)
    chroma, bright = ratio_chroma(blurred, background)
    shadows = shadow_tint(chroma, bright, background, empty, th.shadow_frames)
    colour = table_mask(images, table)
    explained = background_table(blurred, background, colour, max_difference=th.background_difference)
    return HeadScene(
        images=images,
        labels=labels,
        table=explained,
        table_colour=colour,
        known=background.known,
        arm_visibility=arm_visibility(explained, background.known, arms.distal, 20 * scale * scale),
        shadow=shadow_like(
            chroma,
            bright,
            background,
            shadows,
            max_distance=th.shadow_tint_distance,
            ratio_factor=th.shadow_ratio_factor,
        ),
        arms=arms,
        classes=classes,
        scale=scale,
        grip=rig.kinematics.gripper_openings(episode.state),
        colourful=colourful,
        shadows=shadows,
    )


def find_hallucinations(
    episode: Episode, rig: RigConfig, task: str = "", thresholds: Thresholds | None = None
) -> list[Finding]:
    """Every check's first finding (at most one per check), earliest first."""
    th = thresholds or Thresholds()
    scene = head_scene(episode, rig, task, th)
    wrists = {v: f for v, f in episode.images.items() if v != HEAD_VIEW}
    checks = (
        check_views(scene, wrists, th),
        check_arms(scene, th),
        check_objects(scene, th),
        check_wrist_objects(scene, wrists, rig, episode.state, th),
        check_wrist_motion(wrists, rig, episode.state, th),
    )
    found = [f for f in checks if f is not None]
    return sorted(found, key=lambda f: (f.frame, CATEGORIES.index(f.category)))


@dataclass(frozen=True)
class HallucinationDetector:
    """Judge ``auto_hallucination``: ``Verdict(success=None, first_hallucination_frame, reason)``."""

    thresholds: Thresholds = field(default_factory=Thresholds)

    @property
    def judge_id(self) -> str:
        return "auto_hallucination"

    @property
    def kind(self) -> JudgeKind:
        return "vision"

    def judge(self, episode: Episode, context: JudgeContext) -> Verdict:
        found = find_hallucinations(episode, context.rig, context.task, self.thresholds)
        if not found:
            return Verdict(success=None, first_hallucination_frame=None, reason="no hallucination found")
        first = found[0]
        return Verdict(success=None, first_hallucination_frame=int(first.frame), reason=first.reason)
