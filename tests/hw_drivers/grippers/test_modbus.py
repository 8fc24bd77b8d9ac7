"""Modbus RTU framing against the Robotiq 2F-85 manual's example frames."""

from __future__ import annotations

import pytest

from hw_drivers.errors import DeviceProtocolError
from hw_drivers.grippers import modbus

# Robotiq 2F-85 manual, Modbus RTU example: clear rACT, set rACT, read status (activating, activated),
# close at full speed and force, and the FC16 reply.
RESET = "09 10 03 E8 00 03 06 00 00 00 00 00 00 73 30"
ACTIVATE = "09 10 03 E8 00 03 06 01 00 00 00 00 00 72 E1"
READ_STATUS = "09 03 07 D0 00 01 85 CF"
STATUS_ACTIVATING = "09 03 02 11 00 55 D5"
STATUS_ACTIVATED = "09 03 02 31 00 4C 15"
CLOSE = "09 10 03 E8 00 03 06 09 00 00 FF FF FF 42 29"
WRITE_REPLY = "09 10 03 E8 00 03 01 30"
READ_INPUT_3 = "09 04 07 D0 00 03 B1 CE"


def h(s: str) -> bytes:
    return bytes.fromhex(s)


@pytest.mark.parametrize(
    "frame", [RESET, ACTIVATE, READ_STATUS, STATUS_ACTIVATING, STATUS_ACTIVATED, CLOSE, WRITE_REPLY, READ_INPUT_3]
)
def test_crc_matches_the_manual(frame: str) -> None:
    raw = h(frame)
    assert modbus.crc16(raw[:-2]).to_bytes(2, "little") == raw[-2:]
    assert modbus.crc_ok(raw)
    assert not modbus.crc_ok(raw[:-1] + bytes([raw[-1] ^ 1]))


def test_crc_standard_check_value() -> None:
    assert modbus.crc16(b"123456789") == 0x4B37  # CRC-16/MODBUS catalogue check value


def test_requests_match_the_manual() -> None:
    assert modbus.write_request(9, 1000, [0, 0, 0]) == h(RESET)
    assert modbus.write_request(9, 1000, [0x0100, 0, 0]) == h(ACTIVATE)
    assert modbus.write_request(9, 1000, modbus.bytes_to_registers(h("09 00 00 FF FF FF"))) == h(CLOSE)
    assert modbus.read_request(9, 2000, 1) == h(READ_STATUS)
    assert modbus.read_request(9, 2000, 3, modbus.READ_INPUT) == h(READ_INPUT_3)


def test_request_arguments_are_validated() -> None:
    with pytest.raises(ValueError, match="slave"):
        modbus.read_request(0, 2000, 1)
    with pytest.raises(ValueError, match="count"):
        modbus.read_request(9, 2000, 0)
    with pytest.raises(ValueError, match="register"):
        modbus.write_request(9, 1000, [0x10000])
    with pytest.raises(ValueError, match="function"):
        modbus.read_request(9, 2000, 1, function=0x10)


def test_registers_pack_high_byte_first() -> None:
    assert modbus.bytes_to_registers(h("09 00 00 FF 80 40")) == [0x0900, 0x00FF, 0x8040]
    assert modbus.bytes_to_registers(b"\x01") == [0x0100]
    assert modbus.registers_to_bytes([0x0900, 0x00FF]) == h("09 00 00 FF")


def test_parse_replies() -> None:
    assert modbus.parse_reply(h(STATUS_ACTIVATED), slave=9, function=3) == h("31 00")
    assert modbus.parse_reply(h(WRITE_REPLY), slave=9, function=0x10) == h("03 E8 00 03")
    assert modbus.reply_length(h(STATUS_ACTIVATED)[:3]) == 7
    assert modbus.reply_length(h(WRITE_REPLY)[:3]) == 8
    assert modbus.reply_length(h("09 83 02")) == 5
    assert modbus.reply_length(h("09")) is None
    with pytest.raises(DeviceProtocolError, match="unexpected function"):
        modbus.reply_length(h("09 2B 00"))


@pytest.mark.parametrize(
    ("frame", "slave", "function", "match"),
    [
        (STATUS_ACTIVATED[:-3] + " 16", 9, 3, "bad CRC"),
        ("09 03 02", 9, 3, "too short"),
        (STATUS_ACTIVATED, 8, 3, "slave 9, expected 8"),
        (STATUS_ACTIVATED, 9, 4, "function 0x03, expected 0x04"),
        (modbus.with_crc(h("09 03 04 31 00")).hex(" "), 9, 3, "length"),  # byte count 4, 2 sent
    ],
)
def test_malformed_replies_raise_protocol_errors(frame: str, slave: int, function: int, match: str) -> None:
    with pytest.raises(DeviceProtocolError, match=match) as info:
        modbus.parse_reply(h(frame), slave=slave, function=function, device="g")
    assert info.value.device == "g"
    assert not isinstance(info.value, modbus.ModbusExceptionError)


def test_exception_reply_is_typed() -> None:
    reply = modbus.exception_reply(9, 3, modbus.ILLEGAL_ADDRESS)
    assert reply[:3] == h("09 83 02") and modbus.crc_ok(reply)
    with pytest.raises(modbus.ModbusExceptionError, match="illegal data address") as info:
        modbus.parse_reply(reply, slave=9, function=3, device="g")
    assert isinstance(info.value, DeviceProtocolError)
    assert (info.value.function, info.value.code) == (3, 2)


def test_device_side_roundtrip() -> None:
    req = modbus.parse_request(h(CLOSE))
    assert isinstance(req, modbus.Request)
    assert (req.slave, req.function, req.address, req.count, req.data) == (9, 16, 1000, 3, h("09 00 00 FF FF FF"))
    assert modbus.request_length(h(CLOSE)[:7]) == len(h(CLOSE))
    assert modbus.request_length(h(READ_STATUS)[:2]) == 8
    assert modbus.parse_request(modbus.with_crc(h("09 2B 0E 01 00"))) == modbus.ILLEGAL_FUNCTION
    assert modbus.parse_request(modbus.with_crc(h("09 03 07 D0 00 00"))) == modbus.ILLEGAL_VALUE
    assert modbus.write_reply(9, 1000, 3) == h(WRITE_REPLY)
    assert modbus.read_reply(9, 3, h("31 00")) == h(STATUS_ACTIVATED)
