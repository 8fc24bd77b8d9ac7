"""The openpi wire format: msgpack with numpy arrays, and the ALOHA observation dictionary.

Our own implementation of the encoding that openpi's policy server and client speak (see
Physical-Intelligence/openpi ``packages/openpi-client/src/openpi_client/msgpack_numpy.py``):

* an ``ndarray`` travels as a map with **bytes** keys ``{b"__ndarray__": True, b"data": raw bytes,
  b"dtype": dtype.str, b"shape": [...]}`` (C order, the dtype string carries the byte order);
* a numpy scalar travels as ``{b"__npgeneric__": True, b"data": value, b"dtype": dtype.str}``;
* object, void (structured) and complex dtypes are refused on both sides — openpi refuses them so that
  nothing ever falls back to pickle.

The observation follows openpi's ALOHA policy (``src/openpi/policies/aloha_policy.py``): ``state``
float[14], ``images`` {view: uint8[3, H, W]} (CHW) resized with padding to the server's size as
``packages/openpi-client/src/openpi_client/image_tools.py::resize_with_pad`` does, and ``prompt``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import cv2
import msgpack  # type: ignore[import-untyped]  # ships no type information
import numpy as np
from numpy.typing import NDArray

from pilworld.types import Observation

_NDARRAY = b"__ndarray__"
_NPGENERIC = b"__npgeneric__"
# Kinds openpi refuses: void (structured/raw), object (would need pickle), complex.
_REFUSED_KINDS = {"V": "void/structured", "O": "object", "c": "complex"}
DEFAULT_IMAGE_SIZE = (224, 224)  # (height, width) openpi's ALOHA models expect
# Metadata our own server adds (pilworld.policies.openpi.server); a real openpi server sends neither.
PILWORLD_KEY = "pilworld"
RESET_KEY = "pilworld_reset"  # a request that resets the served policy, only sent when the metadata allows


class WireFormatError(ValueError):
    """A message that cannot be encoded or decoded in the openpi wire format."""


def _check_dtype(dtype: np.dtype[Any], where: str) -> None:
    if dtype.kind in _REFUSED_KINDS:
        raise WireFormatError(
            f"{where}: {_REFUSED_KINDS[dtype.kind]} dtype {dtype} cannot travel in the openpi wire format "
            "(only numeric, bool, bytes and str arrays)"
        )


def _encode(obj: Any) -> Any:
    """msgpack ``default`` hook: numpy arrays and scalars as bytes-keyed maps."""
    if isinstance(obj, np.ndarray):
        _check_dtype(obj.dtype, "packb")
        return {_NDARRAY: True, b"data": obj.tobytes(), b"dtype": obj.dtype.str, b"shape": list(obj.shape)}
    if isinstance(obj, np.generic):
        _check_dtype(obj.dtype, "packb")
        return {_NPGENERIC: True, b"data": obj.item(), b"dtype": obj.dtype.str}
    raise TypeError(f"packb: cannot encode {type(obj).__name__} (allowed: dict, list, str, bytes, numbers, numpy)")


def _decode(obj: dict[Any, Any]) -> Any:
    """msgpack ``object_hook``: bytes-keyed array maps back to numpy."""
    if _NDARRAY in obj:
        try:
            dtype = np.dtype(obj[b"dtype"])
            _check_dtype(dtype, "unpackb")
            shape = tuple(int(n) for n in obj[b"shape"])
            data = obj[b"data"]
            expected = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
            if not isinstance(data, bytes) or len(data) != expected:
                got = f"{len(data)} bytes" if isinstance(data, bytes) else type(data).__name__
                raise WireFormatError(
                    f"unpackb: expected {expected} bytes of data for shape {shape} {dtype}, got {got}"
                )
            # A read-only view on the received bytes: no copy of a large image.
            return np.frombuffer(data, dtype=dtype).reshape(shape)
        except (KeyError, TypeError) as err:
            raise WireFormatError(f"unpackb: malformed ndarray map ({type(err).__name__}: {err})") from None
    if _NPGENERIC in obj:
        try:
            dtype = np.dtype(obj[b"dtype"])
            _check_dtype(dtype, "unpackb")
            return dtype.type(obj[b"data"])
        except (KeyError, TypeError) as err:
            raise WireFormatError(f"unpackb: malformed numpy scalar map ({type(err).__name__}: {err})") from None
    return obj


def packb(obj: Any) -> bytes:
    """Serialise nested dicts/lists of numbers, strings, bytes and numpy arrays (openpi's encoding)."""
    # use_bin_type keeps bytes and str apart (msgpack's default since 1.0; spelled out for the wire).
    out = msgpack.packb(obj, default=_encode, use_bin_type=True)
    assert isinstance(out, bytes)
    return out


def unpackb(data: bytes) -> Any:
    """Deserialise what :func:`packb` (or openpi's ``msgpack_numpy.packb``) wrote; arrays are read-only."""
    try:
        return msgpack.unpackb(data, object_hook=_decode, raw=False)
    except WireFormatError:
        raise
    except Exception as err:  # msgpack's own errors (ExtraData, FormatError, …) and bad dtype strings
        raise WireFormatError(f"unpackb: not a valid msgpack message ({type(err).__name__}: {err})") from None


# ---------------------------------------------------------------------------------------------- images


def parse_image_size(value: Any, name: str = "image_size") -> tuple[int, int]:
    """``(height, width)`` from an int (square), a pair ``[height, width]`` or ``{"height", "width"}``."""
    if isinstance(value, Mapping) and {"height", "width"} <= set(value):
        pair: Any = (value["height"], value["width"])
    elif isinstance(value, int) and not isinstance(value, bool):
        pair = (value, value)
    else:
        pair = value
    if (
        not isinstance(pair, list | tuple)
        or len(pair) != 2
        or not all(isinstance(n, int | np.integer) and not isinstance(n, bool) and n > 0 for n in pair)
    ):
        raise ValueError(f"{name}: expected a positive int, [height, width] or {{height, width}}, got {value!r:.80}")
    return int(pair[0]), int(pair[1])


def resize_with_pad(image: NDArray[np.uint8], height: int, width: int) -> NDArray[np.uint8]:
    """``image`` (H, W, C) scaled to fit ``height × width`` keeping its aspect ratio, padded with black.

    The geometry of openpi's ``image_tools.resize_with_pad`` (after ``tf.image.resize_with_pad``):
    ``ratio = max(w / width, h / height)``, the scaled size truncated with ``int()``, the pad split
    with the smaller half on the top/left. openpi resizes with PIL bilinear; we use OpenCV (INTER_AREA
    when shrinking, which like PIL's filter averages the source pixels, INTER_LINEAR when enlarging),
    so pixel values may differ from openpi's by rounding but the layout is identical (and the same as
    :func:`pilworld.config.rig.letterbox`).
    """
    cur_h, cur_w = image.shape[:2]
    if (cur_h, cur_w) == (height, width):
        return image
    ratio = max(cur_w / width, cur_h / height)
    new_h, new_w = max(1, int(cur_h / ratio)), max(1, int(cur_w / ratio))
    interpolation = cv2.INTER_AREA if ratio > 1 else cv2.INTER_LINEAR
    resized = np.asarray(cv2.resize(image, (new_w, new_h), interpolation=interpolation), dtype=image.dtype)
    if resized.ndim == 2:  # cv2 drops a single channel axis
        resized = resized[:, :, None]
    out = np.zeros((height, width, *image.shape[2:]), dtype=image.dtype)
    top, left = (height - new_h) // 2, (width - new_w) // 2
    out[top : top + new_h, left : left + new_w] = resized
    return out


# ---------------------------------------------------------------------------------------------- observations


def observation_to_openpi(
    observation: Observation, instruction: str, image_size: tuple[int, int] = DEFAULT_IMAGE_SIZE
) -> dict[str, Any]:
    """The openpi ALOHA request: ``state`` float32[D], ``images`` {view: uint8[3, h, w]}, ``prompt``.

    ``image_size`` is ``(height, width)``; every view is resized with padding to it, then made CHW.
    """
    height, width = image_size
    images = {
        view: np.ascontiguousarray(resize_with_pad(np.asarray(image), height, width).transpose(2, 0, 1))
        for view, image in observation.images.items()
    }
    return {"state": np.asarray(observation.state, dtype=np.float32), "images": images, "prompt": instruction}


def _image_from_wire(view: str, image: Any) -> NDArray[np.uint8]:
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.ndim != 3:
        got = f"shape {image.shape} dtype {image.dtype}" if isinstance(image, np.ndarray) else type(image).__name__
        raise ValueError(f"images[{view!r}]: expected uint8[3, H, W] (CHW), got {got}")
    if image.shape[0] == 3:
        return np.ascontiguousarray(image.transpose(1, 2, 0))
    if image.shape[2] == 3:  # HWC, as some openpi clients (LIBERO, DROID examples) send
        return image
    raise ValueError(f"images[{view!r}]: expected uint8[3, H, W] (CHW) or [H, W, 3], got shape {image.shape}")


def openpi_to_observation(
    message: Any, image_size: tuple[int, int] | None = None, *, timestamp: float = 0.0
) -> tuple[Observation, str]:
    """The server side: an openpi request back to an :class:`Observation` (HWC images) and its prompt.

    With ``image_size`` (height, width), images of another size are resized with padding to it, so a
    policy built for one resolution can be fed by a client that ignores the server's metadata.
    """
    if not isinstance(message, Mapping):
        raise ValueError(f"request: expected a map with state, images and prompt, got {type(message).__name__}")
    missing = [key for key in ("state", "images") if key not in message]
    if missing:
        raise ValueError(f"request: missing {', '.join(missing)} (got keys {sorted(map(str, message))})")
    raw_images = message["images"]
    if not isinstance(raw_images, Mapping) or not raw_images:
        raise ValueError("request: images must be a non-empty map view -> uint8[3, H, W]")
    images = {}
    for view, image in raw_images.items():
        hwc = _image_from_wire(str(view), image)
        if image_size is not None:
            hwc = resize_with_pad(hwc, *image_size)
        images[str(view)] = hwc
    state = np.asarray(message["state"])
    if not np.issubdtype(state.dtype, np.number) or np.issubdtype(state.dtype, np.complexfloating):
        raise ValueError(f"request: state must be real numbers, got dtype {state.dtype}")
    prompt = message.get("prompt", "")
    if not isinstance(prompt, str):
        raise ValueError(f"request: prompt must be a string, got {type(prompt).__name__}")
    return Observation(images=images, state=state.astype(np.float32), timestamp=timestamp), prompt
