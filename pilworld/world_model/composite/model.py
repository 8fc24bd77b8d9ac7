"""``CompositeWorldModel``: world model v2 behind the :class:`~pilworld.world_model.base.WorldModel` interface.

One chunk: the candidate layers from geometry (:mod:`.layers`), their low-resolution summary through
the U-Net (:mod:`.net`) at ``work_size``, then a full-resolution composite — the robot painted from
its render under the render's exact mask, everything else a per-pixel blend of the sharp candidate
layers by the (upsampled) gates. Deterministic: one pass, no sampling steps, and no averaging of
futures where the layers are sharp — a gate picks a layer, it does not blur two.

It also predicts the state the robot will report (:meth:`predict_with_state`): the arms at the
lagged commands, each gripper at the opening it will measure (resting on an object, not at the
command), which is what the policy and the judges read.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
from numpy.typing import NDArray
from torch import nn
from torch.nn import functional as F

from pilworld.config.rig import RigConfig
from pilworld.control_video.robot_model import RobotModel
from pilworld.perception.colour import segment
from pilworld.types import DEFAULT_VIEWS, HEAD_VIEW, ChunkSpec
from pilworld.world_model.base import PredictRequest, WorldModelBatch, WorldModelInfo
from pilworld.world_model.composite.cache import GRIPS, LAYERS_VERSION, chunk_channels, downsampled
from pilworld.world_model.composite.layers import ChunkLayers, LayerBuilder
from pilworld.world_model.composite.net import N_VIEWS, CompositeUNet, RobotPainter
from pilworld.world_model.composite.object_draw import draw_objects, erase_elsewhere, view_cameras
from pilworld.world_model.composite.objects import ObjectScene, estimate_scene, spec_for
from pilworld.world_model.composite.switches import Switches, token_planes
from simrig.files import SIM_RIG_IN_CHECKOUT, resolve_rig

REPO_ROOT = Path(__file__).resolve().parents[3]


@dataclass(frozen=True)
class CompositeConfig:
    """Sizes of world model v2 and the rig whose geometry it composites."""

    rig: str = SIM_RIG_IN_CHECKOUT  # relative paths resolve against the repository root
    views: tuple[str, ...] = DEFAULT_VIEWS
    image_size: int = 128
    work_size: int = 32  # the U-Net's resolution; the composite is at image_size (training: at the cache's)
    width: int = 16
    future: int = 15
    history: int = 15  # H_h: one round of frames, the head view's memory of what the robot covers now
    layout: int = LAYERS_VERSION  # the layer code's version the weights were trained with (their input channels)
    objects: bool = True  # track the task's objects as rigid bodies (:mod:`.objects`); False: the blend alone
    switches: Switches = field(default_factory=Switches)  # what of the recipe a variant keeps (default: all)

    def __post_init__(self) -> None:
        if self.image_size % self.work_size or self.work_size % 4:
            raise ValueError(
                f"work_size: {self.work_size} must divide image_size {self.image_size} and be a multiple of 4"
            )
        if len(self.views) != N_VIEWS:
            raise ValueError(f"views: expected {N_VIEWS} camera keys, got {self.views!r}")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["views"] = list(self.views)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> CompositeConfig:
        known = {f for f in cls.__dataclass_fields__}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"composite config: unknown keys {unknown}")
        if d.get("layout", 0) != LAYERS_VERSION:
            raise ValueError(
                f"composite config: the weights were trained on layer version {d.get('layout', 'before 4')}, this code "
                f"builds version {LAYERS_VERSION}; retrain them (pilworld train composite) or use the matching release"
            )
        switches = Switches.from_dict(d.get("switches"))
        return cls(**{**d, "views": tuple(d.get("views", DEFAULT_VIEWS)), "switches": switches})

    def rig_path(self) -> Path:
        return resolve_rig(self.rig, REPO_ROOT)


# Base channel layout (see cache.chunk_channels): prior 0-2, prior valid 3, current 4-6, carry L 7-9, valid 10,
# carry R 11-13, valid 14, part one-hot 15-18 (L arm, L fingers, R arm, R fingers), shade 19, depth 20,
# memory 21-23, memory valid 24, hand region 25.
_PARTS, _SHADE, _DEPTH = slice(15, 19), slice(19, 20), slice(20, 21)


LOST_MIN_PX = 4  # an object at rest whose visible silhouette covers fewer pixels is not checked
LOST_SHARE = 0.5  # … and one whose colour shows on less than this share of it (±2 px) was lost by the blend
_NEAR = np.ones((5, 5), np.uint8)


def _table_colour(image: NDArray[np.uint8], plate: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """A wrist view's empty scene: its table colour (moderately saturated, bright pixels), else the plate's."""
    hsv = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2HSV)
    table = (hsv[..., 1] >= 18) & (hsv[..., 1] < 60) & (hsv[..., 2] > 120)
    rgb = np.median(image[table], axis=0) if table.sum() > 50 else np.median(plate.reshape(-1, 3), axis=0)
    return np.broadcast_to(rgb.astype(np.uint8), image.shape).copy()


def net_inputs(
    base: torch.Tensor, scal: torch.Tensor, markers: torch.Tensor | None = None, actions: torch.Tensor | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Base channels (N, 26, h, w) uint8 + scalars (N, 8) → network input (N, 36, h, w), commanded grips (N, 2).

    A variant's extra planes come last: ``markers`` (N, 3, h, w) uint8, the paper's Γ (zero in the wrist
    views), then ``actions`` (N, 14), the frame's commanded action as token planes (:mod:`.switches`).
    """
    x = base.float() / 255.0 if base.dtype == torch.uint8 else base / 255.0
    n, _, h, w = x.shape
    view = F.one_hot(scal[:, 5].long(), N_VIEWS).float()
    grips = scal[:, 6:8]
    planes = torch.cat([scal[:, :5], view, grips], 1)[:, :, None, None].expand(n, -1, h, w)
    parts = [x, planes]
    if markers is not None:
        parts.append(markers.float() / 255.0 if markers.dtype == torch.uint8 else markers)
    if actions is not None:
        parts.append(token_planes(actions)[:, :, None, None].expand(n, -1, h, w))
    return torch.cat(parts, 1), grips


def _plate_at(plate: torch.Tensor, w: int) -> torch.Tensor:
    return plate if plate.shape[-1] == w else F.adaptive_avg_pool2d(plate[None], (w, w))[0]


def _image(x: torch.Tensor, first: int) -> torch.Tensor:
    """Channels ``first … first+2`` of the base as an RGB image in [0, 1] (uint8 bases are converted here,
    channel group by channel group: the whole base in float is the slowest step of a chunk)."""
    c = x[:, first : first + 3]
    return c.float() / 255.0 if c.dtype == torch.uint8 else c


def _flag(x: torch.Tensor, channel: int) -> torch.Tensor:
    c = x[:, channel]
    return c > 127 if c.dtype == torch.uint8 else c > 0.5


def candidates(
    x: torch.Tensor, generated: torch.Tensor, plate: torch.Tensor, view: torch.Tensor
) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
    """Base channels (uint8, or float in [0, 1]) → the candidate images (each (N, 3, h, w) in [0, 1]) and their
    validity (each (N, h, w) bool), in CANDIDATES order. ``plate`` (3, H, W) in [0, 1] is valid in the head
    view (``view`` index 0) only."""
    n, _, h, w = x.shape
    plates = _plate_at(plate, w)[None].expand(n, -1, -1, -1)
    head = (view == 0)[:, None, None].expand(n, h, w)
    images = [_image(x, 0), _image(x, 7), _image(x, 11), generated, plates, _image(x, 21)]
    valid = [_flag(x, 3), _flag(x, 10), _flag(x, 14), torch.ones_like(head), head, _flag(x, 24)]
    return images, valid


def _at_resolution(
    gates: torch.Tensor, generated: torch.Tensor, size: tuple[int, int]
) -> tuple[torch.Tensor, torch.Tensor]:
    """Gates and generated fill upsampled to the layers' (h, w): they choose between full-resolution layers."""
    if tuple(gates.shape[-2:]) == size:
        return gates, generated
    return (
        F.interpolate(gates, size=size, mode="bilinear", align_corners=False),
        F.interpolate(generated, size=size, mode="bilinear", align_corners=False),
    )


def blend(
    x: torch.Tensor,
    scal: torch.Tensor,
    gates: torch.Tensor,
    generated: torch.Tensor,
    painter: RobotPainter,
    plate: torch.Tensor,
    paste: bool = True,
) -> torch.Tensor:
    """The composite (training's, differentiable) at the resolution of the float base channels ``x`` in
    [0, 1]; gates and generated are resized to it. Inference uses :func:`blend_bytes`, the same rounded.

    ``paste`` False (a variant): the robot is not painted from its render; its pixels are left to the gates."""
    gates, generated = _at_resolution(gates, generated, (x.shape[-2], x.shape[-1]))
    images, valid = candidates(x, generated, plate, scal[:, 5])
    # Away from the hands nothing moves: the prior where it has the pixel, else the memory; the gates decide
    # only near the tools' paths (and where neither layer has the pixel, e.g. where the robot was all round).
    prior_ok, memory_ok = valid[0], valid[5]
    kept = torch.where(prior_ok[:, None], images[0], images[5])
    parts = x[:, _PARTS]
    free = _flag(x, 25) | ~(prior_ok | memory_ok)
    if not paste:  # where the robot will be, the gates choose too (nothing pastes it)
        free = free | (parts.sum(1) > 0.5)
    weights = torch.softmax(gates.masked_fill(~torch.stack(valid, 1), -1e4), 1)
    mixed = weights[:, 0:1] * images[0]
    for c in range(1, len(images)):  # a running sum: no (N, C, 3, h, w) stack of the candidates
        mixed = mixed + weights[:, c : c + 1] * images[c]
    scene = torch.where(free[:, None], mixed, kept)
    if not paste:
        return scene
    robot = painter(parts, x[:, _SHADE], x[:, _DEPTH], scal[:, 5])
    mask = parts.sum(1, keepdim=True).clamp(0, 1)
    out: torch.Tensor = mask * robot + (1 - mask) * scene
    return out


def blend_bytes(
    x: torch.Tensor,
    scal: torch.Tensor,
    gates: torch.Tensor,
    generated: torch.Tensor,
    painter: RobotPainter,
    plate: torch.Tensor,
    paste: bool = True,
) -> torch.Tensor:
    """Inference's :func:`blend` on uint8 base channels, straight to uint8 frames (N, 3, h, w).

    The same composite as ``round(255 · blend(x / 255))`` with less work: a candidate that is valid nowhere in
    the chunk (the carry layers when objects are tracked, the plate without the head view) gets weight
    exactly 0 in :func:`blend`'s softmax, so it is left out of the softmax and the sum; the robot's pixels
    are looked up in the painter's table at those pixels only.
    """
    h, w = x.shape[-2:]
    gates, generated = _at_resolution(gates, generated, (h, w))
    n = x.shape[0]
    prior_ok, memory_ok = _flag(x, 3), _flag(x, 24)
    head = (scal[:, 5] == 0)[:, None, None]
    # validity of each candidate in CANDIDATES order (None: valid everywhere); images made only if used
    valid: list[torch.Tensor | None] = [prior_ok, _flag(x, 10), _flag(x, 14), None, head.expand(n, h, w), memory_ok]
    used = [c for c, ok in enumerate(valid) if ok is None or bool(ok.any())]

    def image(c: int) -> torch.Tensor:
        if c == 3:
            return generated
        if c == 4:
            return _plate_at(plate, w)[None].expand(n, -1, -1, -1)
        return _image(x, (0, 7, 11, -1, -1, 21)[c])

    mask = torch.zeros((n, len(used), h, w), dtype=torch.bool)
    for i, c in enumerate(used):
        ok = valid[c]
        if ok is not None:
            mask[:, i] = ~ok
    weights = torch.softmax(gates[:, used].masked_fill(mask, -1e4), 1)
    images = {c: image(c) for c in used}
    mixed = weights[:, 0:1] * images[used[0]]
    for i, c in enumerate(used[1:], 1):  # blend's running sum, less the terms that are exactly 0
        mixed = mixed + weights[:, i : i + 1] * images[c]
    prior = images[0] if 0 in images else _image(x, 0)
    memory = images[5] if 5 in images else _image(x, 21)
    kept = torch.where(prior_ok[:, None], prior, memory)
    onehot = x[:, _PARTS] > 127
    free = _flag(x, 25) | ~(prior_ok | memory_ok)
    if not paste:
        free = free | onehot.any(1)
    scene = torch.where(free[:, None], mixed, kept)
    out = (scene.clamp(0, 1) * 255.0).round().to(torch.uint8)
    if not paste:
        return out
    # an exact render: one part per pixel, ids 1 … 4 from the one-hot channels
    ids = (onehot * torch.arange(1, onehot.shape[1] + 1, dtype=torch.uint8)[None, :, None, None]).amax(1)
    k, yy, xx = (ids > 0).nonzero(as_tuple=True)
    if len(k):
        shade, depth = x[k, _SHADE.start, yy, xx], x[k, _DEPTH.start, yy, xx]
        colour = painter.paint_points(ids[k, yy, xx], shade, depth, scal[k, 5])
        out[k, :, yy, xx] = (colour.clamp(0, 1) * 255.0).round().to(torch.uint8)
    return out


class CompositeWorldModel(nn.Module):
    """World model v2; see the module docstring. ``bind_rig`` swaps in a (re)calibrated rig's geometry."""

    def __init__(self, config: CompositeConfig, rig: RigConfig | None = None) -> None:
        super().__init__()
        self.config = config
        self.net = CompositeUNet(config.width, config.work_size, config.switches.extra_channels)
        self.painter = RobotPainter()
        # The head camera's empty scene (table and background, no robot, no objects), RGB in [0, 1]: set from
        # the training data (robot-masked per-pixel median, :func:`.plate.estimate_plate`), saved with the weights.
        self.plate: torch.Tensor
        self.register_buffer("plate", torch.zeros(3, config.image_size, config.image_size))
        self._rig = rig
        self._robot: RobotModel | None = None  # bind_rig's robot model; None: the rig's
        self._builder: LayerBuilder | None = None
        self._scene: ObjectScene | None = None  # the rollout's objects (begin_rollout), advanced per chunk
        self._scene_key: tuple[str, NDArray[np.float32]] | None = None  # the request that continues it

    @property
    def switches(self) -> Switches:
        return self.config.switches

    @property
    def info(self) -> WorldModelInfo:
        c = self.config
        return WorldModelInfo(
            views=c.views, height=c.image_size, width=c.image_size, future=c.future, history=c.history
        )

    def bind_rig(self, rig: RigConfig, *, robot: RobotModel | None = None) -> None:
        """Composite with ``rig``'s robot model and cameras (default: the rig the model was trained on).

        ``robot``: render this robot model instead of ``rig``'s (a mismatched one, for the stability probes;
        a wrong camera calibration is a rig of its own, :func:`pilworld.control_video.probes.perturbed_rig`)."""
        if (rig.image_size.width, rig.image_size.height) != (self.config.image_size, self.config.image_size):
            raise ValueError(
                f"rig {rig.name!r}: image size {rig.image_size} differs from the model's {self.config.image_size}"
            )
        self._rig = rig
        self._robot = robot
        self._builder = None
        self._scene = None

    def begin_rollout(
        self, current: dict[str, NDArray[np.uint8]], state: NDArray[np.floating], instruction: str
    ) -> None:
        """Start an imagined rollout: estimate its objects from the start frames, to be carried chunk by chunk.

        The imagined branch calls this at its reset. Requests that continue the rollout (the state this
        model predicted last, the same instruction) use the carried objects; any other request gets
        objects estimated from its own frames.
        """
        self._scene = None
        self._scene_key = None
        if not self.config.objects:
            return
        self._scene = estimate_scene(self.builder.rig, instruction, dict(current), state)
        if self._scene is not None:
            self._scene_key = (instruction, np.asarray(state, np.float32).copy())

    def _scene_for(self, request: PredictRequest) -> ObjectScene | None:
        assert request.state is not None
        key = self._scene_key
        if (
            self._scene is not None
            and key is not None
            and key[0] == request.instruction
            and np.allclose(key[1], np.asarray(request.state, np.float32), atol=1e-5)
        ):
            return self._scene
        if not self.config.objects:
            return None
        return estimate_scene(self.builder.rig, request.instruction, dict(request.current), request.state)

    @property
    def builder(self) -> LayerBuilder:
        if self._builder is None:
            rig = self._rig or RigConfig.load(self.config.rig_path())
            self._builder = LayerBuilder(rig, ChunkSpec(frames=self.config.future), robot=self._robot)
        return self._builder

    # ------------------------------------------------------------------ inference

    @torch.no_grad()
    def predict_with_state(
        self, request: PredictRequest, *, steps: int | None = None, seed: int = 0
    ) -> tuple[dict[str, NDArray[np.uint8]], NDArray[np.float32]]:
        """One chunk: view → uint8 (K, H, W, 3), and the (K, 14) state the robot will report."""
        if request.state is None:
            raise ValueError("state: world model v2 needs the current joint state (PredictRequest.build(..., state=))")
        head = self.config.views[0]
        scene = self._scene_for(request)
        resting = None
        if scene is not None:
            held = (scene.held(0), scene.held(1))
            resting = (None if held[0] is None else held[0].grip, None if held[1] is None else held[1].grip)
        layers = self.builder(
            dict(request.current),
            request.state,
            request.actions,
            {head: request.history[head]},
            request.history_state,
            request.history_valid,
            resting=resting,
            with_carry=scene is None,
        )
        base_np, scal_np = chunk_channels(layers, dict(request.current), self.config.views)
        base, scal = torch.from_numpy(base_np), torch.from_numpy(scal_np)
        s = self.config.work_size
        # The network's input, area-averaged one channel at a time in uint8 as the training cache is.
        small = torch.from_numpy(np.stack([downsampled(row, s) for row in base_np]))
        sw = self.switches
        K = self.config.future
        markers, actions = self._variant_inputs(request, s) if sw.extra_channels else (None, None)
        inp, cmd = net_inputs(sw.apply(small), scal, markers, actions)
        gates, generated, grips = self.net(inp, cmd)
        blended = blend_bytes(sw.apply(base), scal, gates, generated, self.painter, self.plate, sw.paste)
        frames = blended.permute(0, 2, 3, 1).numpy()
        by_view = {v: frames[i * K : (i + 1) * K] for i, v in enumerate(self.config.views)}
        states = layers.poses.astype(np.float32).copy()
        # Each gripper's opening from its own wrist view's prediction (it sees the fingers and what they hold).
        g = grips.clamp(0, 1).numpy().reshape(len(self.config.views), K, 2)
        for side, grip_index in zip((0, 1), GRIPS, strict=True):
            view_index = 1 + side if len(self.config.views) > 2 else 0
            states[:, grip_index] = g[view_index, :, side]
        if scene is not None:
            by_view, grips_measured = self._objects(scene, request, layers, by_view)
            states[:, list(GRIPS)] = grips_measured
            if scene is self._scene:
                self._scene_key = (request.instruction, states[-1].copy())
        return by_view, states

    def _variant_inputs(self, request: PredictRequest, size: int) -> tuple[torch.Tensor | None, torch.Tensor | None]:
        """A variant's extra inputs, view-major like the base rows: the head view's Γ at ``size`` (the
        request's control video; zero in the wrist views) and the commanded actions of each frame."""
        sw, K, V = self.switches, self.config.future, len(self.config.views)
        markers = None
        if sw.markers:
            m = np.zeros((V * K, 3, size, size), np.uint8)
            for k in range(K):
                m[k] = downsampled(np.asarray(request.control[k]).transpose(2, 0, 1), size)
            markers = torch.from_numpy(m)
        actions = (
            torch.from_numpy(np.tile(np.asarray(request.actions, np.float32), (V, 1))) if sw.action_tokens else None
        )
        return markers, actions

    def _objects(
        self,
        scene: ObjectScene,
        request: PredictRequest,
        layers: ChunkLayers,
        by_view: dict[str, NDArray[np.uint8]],
    ) -> tuple[dict[str, NDArray[np.uint8]], NDArray[np.float32]]:
        """Advance the tracked objects along the chunk and draw the moving ones into every view."""
        assert request.state is not None
        seq = np.concatenate([np.asarray(request.state, np.float64)[None], layers.poses])
        poses, grips, moved = scene.advance(seq, np.asarray(request.actions, np.float64))
        rig = self.builder.rig
        spec = spec_for(request.instruction)
        assert spec is not None
        plate = (self.plate.permute(1, 2, 0).numpy() * 255.0).round().astype(np.uint8)
        out: dict[str, NDArray[np.uint8]] = {}
        objects = scene.objects
        colours = [spec.object(o.name).colour for o in objects]
        for view, frames in by_view.items():
            cams = view_cameras(rig, view, layers.poses)
            if cams is None or not objects:
                out[view] = frames
                continue
            head = view == HEAD_VIEW
            background = plate if head else _table_colour(np.asarray(request.current[view]), plate)
            # Ours to draw: in a wrist view every object (a turning wrist camera's reprojection loses what leaves
            # its view); in the head view the moving ones, and any at rest that the blend lost (an arm passing
            # over it), while those it shows keep their real pixels.
            erase = [not head or o.name in moved for o in objects]
            new = frames.copy()
            for k, cam in enumerate(cams):
                drawn = [(o.shape, poses[k][i], o.colour) for i, o in enumerate(objects)]
                depth = np.asarray(layers.depth[view][k], np.float32)
                img, masks = draw_objects(new[k], cam, drawn, depth)
                use = list(erase)
                if head and not all(use):
                    seen = segment(new[k], [c for c, e in zip(colours, erase, strict=True) if not e])
                    for i, o in enumerate(objects):
                        m = masks[i]
                        if not use[i] and m.sum() >= LOST_MIN_PX:
                            near = cv2.dilate(m.astype(np.uint8), _NEAR) > 0  # an estimate a pixel or two off
                            use[i] = float((seen[o.name] & near).sum()) < LOST_SHARE * float(m.sum())
                frame = new[k].copy()
                for i in range(len(objects)):
                    if use[i]:
                        frame[masks[i]] = img[masks[i]]
                robot = np.asarray(layers.parts[view][k]) > 0
                ours = [i for i in range(len(objects)) if erase[i]]
                new[k] = erase_elsewhere(frame, [colours[i] for i in ours], [masks[i] for i in ours], robot, background)
            out[view] = new
        return out, grips.astype(np.float32)

    def predict(
        self, request: PredictRequest, *, steps: int | None = None, seed: int = 0
    ) -> dict[str, NDArray[np.uint8]]:
        return self.predict_with_state(request, steps=steps, seed=seed)[0]

    def predict_batch(self, batch: WorldModelBatch, *, steps: int | None = None, seed: int = 0) -> torch.Tensor:
        """uint8 [B, V, K, 3, H, W]; the batch must carry ``state`` (the current joint state of each sample)."""
        batch.check(self.info)
        if batch.state is None:
            raise ValueError("state: world model v2 needs the current joint state of every sample (batch.state)")
        outs = []
        for b in range(batch.size):
            req = PredictRequest.build(
                self.info,
                current={v: batch.current[b, i].permute(1, 2, 0).numpy() for i, v in enumerate(self.config.views)},
                history=None,
                control=batch.control[b].permute(0, 2, 3, 1).numpy(),
                actions=batch.actions[b].numpy(),
                instruction=batch.instruction[b],
                state=batch.state[b].numpy(),
            )
            frames = self.predict(req, seed=seed)
            outs.append(torch.stack([torch.from_numpy(frames[v]).permute(0, 3, 1, 2) for v in self.config.views]))
        return torch.stack(outs)

    def train_forward(
        self,
        base: torch.Tensor,
        scal: torch.Tensor,
        markers: torch.Tensor | None = None,
        actions: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Training: cached base channels at ``work_size`` → (composite (N, 3, h, w), grips (N, 2)); a variant's
        switches apply here, with its ``markers`` and ``actions`` from the cache's extras."""
        sw = self.switches
        if sw.markers != (markers is not None) or sw.action_tokens != (actions is not None):
            raise ValueError(
                f"switches ({sw.describe()}): expected markers={sw.markers} and actions={sw.action_tokens}, "
                f"got markers={markers is not None} and actions={actions is not None}"
            )
        x = sw.apply(base)
        inp, cmd = net_inputs(x, scal, markers, actions)
        gates, generated, grips = self.net(inp, cmd)
        return blend(x.float() / 255.0, scal, gates, generated, self.painter, self.plate, sw.paste), grips
