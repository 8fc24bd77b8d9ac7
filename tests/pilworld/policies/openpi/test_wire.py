"""The openpi wire format: msgpack with bytes-keyed ndarray maps, resize-with-pad, the ALOHA request."""

from __future__ import annotations

from typing import Any

import msgpack  # type: ignore[import-untyped]
import numpy as np
import pytest

from pilworld.policies.openpi.wire import (
    observation_to_openpi,
    openpi_to_observation,
    packb,
    parse_image_size,
    resize_with_pad,
    unpackb,
)
from pilworld.types import Observation

DTYPES = ["uint8", "int16", "int64", "float16", "float32", "float64", "bool", ">f8", "<u4", "U5", "S3"]


def _array(dtype: str, shape: tuple[int, ...] = (2, 3)) -> np.ndarray:
    if dtype.startswith(("U", "S")):
        return np.array(["ab", "c", "", "xyz", "q", "w"], dtype=dtype).reshape(shape)
    return (
        (np.arange(int(np.prod(shape))) % 2 if dtype == "bool" else np.arange(np.prod(shape)) * 3 - 4)
        .astype(dtype)
        .reshape(shape)
    )


def _assert_same(a: Any, b: Any) -> None:
    if isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape
        np.testing.assert_array_equal(a, b)
    elif isinstance(a, np.generic):
        assert type(a) is type(b) and a == b
    elif isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b)
        for key in a:
            _assert_same(a[key], b[key])
    elif isinstance(a, list | tuple):
        assert isinstance(b, list) and len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            _assert_same(x, y)
    else:
        assert a == b and type(a) is type(b)


@pytest.mark.parametrize("dtype", DTYPES)
def test_arrays_round_trip_exactly(dtype: str) -> None:
    arr = _array(dtype)
    out = unpackb(packb(arr))
    _assert_same(arr, out)
    assert out.dtype.str == np.dtype(dtype).str  # byte order kept


def test_nested_messages_round_trip() -> None:
    msg = {
        "state": np.linspace(-1, 1, 14, dtype=np.float32),
        "images": {"cam_high": np.arange(3 * 4 * 5, dtype=np.uint8).reshape(3, 4, 5)},
        "prompt": "stack the bowls",
        "scalars": [np.float32(1.5), np.int64(-7), np.bool_(True)],
        "plain": {"n": 3, "x": 0.25, "b": b"\x00\x01", "none": None, "list": [1, "two"]},
        "empty": np.zeros((0, 14), dtype=np.float32),
        "zero_d": np.array(2.5),
        "strided": np.arange(40, dtype=np.int32).reshape(5, 8)[:, ::3],  # not contiguous
        b"bytes_key": 1,
    }
    _assert_same(msg, unpackb(packb(msg)))


def test_encoding_uses_bytes_keys() -> None:
    arr = np.arange(6, dtype="<f4").reshape(2, 3)
    raw = msgpack.unpackb(packb({"a": arr, "s": np.int16(3)}))
    assert raw["a"] == {b"__ndarray__": True, b"data": arr.tobytes(), b"dtype": "<f4", b"shape": [2, 3]}
    assert raw["s"] == {b"__npgeneric__": True, b"data": 3, b"dtype": "<i2"}


def test_decodes_maps_packed_by_hand_the_openpi_way() -> None:
    # What openpi_client.msgpack_numpy.packb writes, built with plain msgpack.
    arr = np.random.default_rng(0).normal(size=(50, 14))
    frame = msgpack.packb(
        {
            "actions": {b"__ndarray__": True, b"data": arr.tobytes(), b"dtype": arr.dtype.str, b"shape": (50, 14)},
            "step": {b"__npgeneric__": True, b"data": 7, b"dtype": np.dtype(np.int64).str},
        }
    )
    out = unpackb(frame)
    _assert_same(arr, out["actions"])
    assert out["step"] == 7 and isinstance(out["step"], np.int64)


@pytest.mark.parametrize(
    "value",
    [np.array([object()], dtype=object), np.array([1 + 2j]), np.zeros(2, dtype=[("a", "<i4")]), np.complex64(1)],
)
def test_unsupported_dtypes_are_refused(value: Any) -> None:
    with pytest.raises(ValueError, match="cannot travel in the openpi wire format"):
        packb({"x": value})


def test_unsupported_and_malformed_maps_are_refused_on_arrival() -> None:
    complex_map = {b"__ndarray__": True, b"data": np.zeros(2, np.complex64).tobytes(), b"dtype": "<c8", b"shape": [2]}
    with pytest.raises(ValueError, match="complex dtype"):
        unpackb(msgpack.packb(complex_map))
    short = {b"__ndarray__": True, b"data": b"\x00" * 7, b"dtype": "<f4", b"shape": [2]}
    with pytest.raises(ValueError, match="expected 8 bytes of data"):
        unpackb(msgpack.packb(short))
    with pytest.raises(ValueError, match="malformed ndarray map"):
        unpackb(msgpack.packb({b"__ndarray__": True, b"dtype": "<f4"}))
    with pytest.raises(ValueError, match="not a valid msgpack message"):
        unpackb(b"\xc1garbage")


def test_resize_with_pad_keeps_aspect_and_pads_black() -> None:
    image = np.full((96, 128, 3), (200, 100, 50), dtype=np.uint8)  # 4:3, wider than tall
    out = resize_with_pad(image, 224, 224)
    # openpi's geometry: ratio = max(128/224, 96/224); 128 -> 224, 96 -> int(168.0) = 168; pad 28 top/bottom.
    assert out.shape == (224, 224, 3) and out.dtype == np.uint8
    assert not out[:28].any() and not out[196:].any()
    np.testing.assert_array_equal(out[28:196], np.broadcast_to(image[:1, :1], (168, 224, 3)))
    tall = resize_with_pad(np.full((100, 50, 3), 255, np.uint8), 64, 64)  # -> 64×32, pad 16 left/right
    assert not tall[:, :16].any() and not tall[:, 48:].any() and (tall[:, 16:48] == 255).all()
    same = np.zeros((64, 64, 3), np.uint8)
    assert resize_with_pad(same, 64, 64) is same


def test_observation_request_is_chw_at_the_servers_size_and_comes_back() -> None:
    rng = np.random.default_rng(1)
    images = {v: rng.integers(0, 256, (96, 128, 3), dtype=np.uint8) for v in ("cam_high", "cam_left_wrist")}
    obs = Observation(images=images, state=np.arange(14, dtype=np.float32), timestamp=3.0)
    msg = observation_to_openpi(obs, "sort the cubes", (224, 224))
    assert msg["prompt"] == "sort the cubes" and msg["state"].dtype == np.float32
    for view, chw in msg["images"].items():
        assert chw.shape == (3, 224, 224) and chw.dtype == np.uint8 and chw.flags.c_contiguous
        np.testing.assert_array_equal(chw.transpose(1, 2, 0), resize_with_pad(images[view], 224, 224))
    back, prompt = openpi_to_observation(unpackb(packb(msg)))
    assert prompt == "sort the cubes" and back.views == obs.views
    np.testing.assert_array_equal(back.images["cam_high"], resize_with_pad(images["cam_high"], 224, 224))
    # At the native size nothing is resized: the server sees exactly the client's pixels.
    same, _ = openpi_to_observation(unpackb(packb(observation_to_openpi(obs, "x", (96, 128)))))
    np.testing.assert_array_equal(same.images["cam_left_wrist"], images["cam_left_wrist"])
    np.testing.assert_array_equal(same.state, obs.state)


def test_server_side_decoding_checks_the_request() -> None:
    hwc = np.zeros((8, 10, 3), np.uint8)
    obs, prompt = openpi_to_observation({"state": np.ones(14), "images": {"cam_high": hwc}})
    assert obs.images["cam_high"].shape == (8, 10, 3) and obs.state.dtype == np.float32 and prompt == ""
    resized, _ = openpi_to_observation({"state": np.ones(14), "images": {"cam_high": hwc}}, (16, 16))
    assert resized.images["cam_high"].shape == (16, 16, 3)
    with pytest.raises(ValueError, match=r"images\['cam_high'\]: expected uint8\[3, H, W\]"):
        openpi_to_observation({"state": np.ones(14), "images": {"cam_high": np.zeros((3, 8, 8), np.float32)}})
    with pytest.raises(ValueError, match="missing images"):
        openpi_to_observation({"state": np.ones(14)})
    with pytest.raises(ValueError, match="prompt must be a string"):
        openpi_to_observation({"state": np.ones(14), "images": {"a": hwc}, "prompt": 3})


def test_parse_image_size() -> None:
    assert parse_image_size(224) == (224, 224)
    assert parse_image_size([96, 128]) == (96, 128)
    assert parse_image_size({"height": 96, "width": 128}) == (96, 128)
    with pytest.raises(ValueError, match="image_size"):
        parse_image_size([0, 3])
