"""A small Modbus RTU framing layer: CRC-16/MODBUS, the three requests a Robotiq gripper needs, replies.

Only what the 2F-85 speaks: FC03/FC04 (read holding/input registers) and FC16 (write multiple
registers). Frames are ``slave | function | payload | CRC`` with 16-bit registers big-endian and the
CRC little-endian. Both sides use this module: the driver builds requests and parses replies; the fake
device (:mod:`hw_drivers.fakes.robotiq`) parses requests and builds replies, so a framing bug would
show up as a disagreement with the manual's example frames in the tests, not as a silent agreement.

Malformed replies raise :class:`~hw_drivers.errors.DeviceProtocolError` (the driver retries those);
a well-formed exception reply raises :class:`ModbusExceptionError`, a protocol error the driver does
not retry (the device understood and refused).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from hw_drivers.errors import DeviceProtocolError

READ_HOLDING = 0x03
READ_INPUT = 0x04
WRITE_MULTIPLE = 0x10
EXCEPTION_FLAG = 0x80

ILLEGAL_FUNCTION = 0x01
ILLEGAL_ADDRESS = 0x02
ILLEGAL_VALUE = 0x03
EXCEPTION_NAMES = {
    ILLEGAL_FUNCTION: "illegal function",
    ILLEGAL_ADDRESS: "illegal data address",
    ILLEGAL_VALUE: "illegal data value",
    0x04: "slave device failure",
    0x06: "slave device busy",
}

# Modbus limits per request (spec): 125 registers read, 123 written.
MAX_READ = 125
MAX_WRITE = 123


class ModbusExceptionError(DeviceProtocolError):
    """The device answered with a Modbus exception (``code``) to ``function``."""

    def __init__(self, device: str, function: int, code: int) -> None:
        name = EXCEPTION_NAMES.get(code, "unknown exception")
        super().__init__(device, f"Modbus exception {code:#04x} ({name}) to function {function:#04x}")
        self.function = function
        self.code = code


def crc16(data: bytes) -> int:
    """CRC-16/MODBUS (poly 0xA001 reflected, init 0xFFFF)."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return crc


def with_crc(body: bytes) -> bytes:
    return body + crc16(body).to_bytes(2, "little")


def crc_ok(frame: bytes) -> bool:
    return len(frame) >= 4 and crc16(frame[:-2]).to_bytes(2, "little") == frame[-2:]


def _check_range(name: str, value: int, low: int = 0, high: int = 255) -> None:
    if not low <= value <= high:
        raise ValueError(f"{name}: expected {low} … {high}, got {value}")


def read_request(slave: int, address: int, count: int, function: int = READ_HOLDING) -> bytes:
    """FC03/FC04: read ``count`` registers from ``address``."""
    _check_range("slave", slave, 1, 247)
    _check_range("address", address, 0, 0xFFFF)
    _check_range("count", count, 1, MAX_READ)
    if function not in (READ_HOLDING, READ_INPUT):
        raise ValueError(f"function: expected 3 or 4, got {function}")
    return with_crc(bytes([slave, function]) + address.to_bytes(2, "big") + count.to_bytes(2, "big"))


def write_request(slave: int, address: int, registers: Sequence[int]) -> bytes:
    """FC16: write ``registers`` (16-bit values) from ``address``."""
    _check_range("slave", slave, 0, 247)  # 0 = broadcast (no reply)
    _check_range("address", address, 0, 0xFFFF)
    _check_range("register count", len(registers), 1, MAX_WRITE)
    for r in registers:
        _check_range("register", r, 0, 0xFFFF)
    data = b"".join(r.to_bytes(2, "big") for r in registers)
    head = bytes([slave, WRITE_MULTIPLE]) + address.to_bytes(2, "big") + len(registers).to_bytes(2, "big")
    return with_crc(head + bytes([len(data)]) + data)


def bytes_to_registers(data: bytes) -> list[int]:
    """Pairs of bytes, high byte first (how Robotiq packs its byte-wide fields into registers)."""
    if len(data) % 2:
        data = data + b"\x00"
    return [int.from_bytes(data[i : i + 2], "big") for i in range(0, len(data), 2)]


def registers_to_bytes(registers: Sequence[int]) -> bytes:
    return b"".join(r.to_bytes(2, "big") for r in registers)


# ------------------------------------------------------------------------------------------------ replies


def reply_length(head: bytes, device: str = "modbus") -> int | None:
    """The full length of a reply that starts with ``head``, or None if more bytes are needed to tell.

    Every reply is at least 5 bytes (an exception reply is exactly 5), so a reader can ask for 5 bytes
    first and then for the rest. Unknown function codes raise: the stream is out of step.
    """
    if len(head) < 3:
        return None
    function = head[1]
    if function & EXCEPTION_FLAG:
        return 5
    if function in (READ_HOLDING, READ_INPUT):
        return 5 + head[2]
    if function == WRITE_MULTIPLE:
        return 8
    raise DeviceProtocolError(device, f"reply with unexpected function code {function:#04x}")


def parse_reply(frame: bytes, *, slave: int, function: int, device: str = "modbus") -> bytes:
    """Check a reply to ``function`` from ``slave``; return its payload.

    FC03/FC04: the register bytes. FC16: the echoed ``address | count`` (4 bytes).
    """
    if len(frame) < 5:
        raise DeviceProtocolError(device, f"reply too short ({len(frame)} bytes): {frame.hex(' ')}")
    if not crc_ok(frame):
        raise DeviceProtocolError(device, f"bad CRC in reply {frame.hex(' ')}")
    if frame[0] != slave:
        raise DeviceProtocolError(device, f"reply from slave {frame[0]}, expected {slave}")
    if frame[1] == function | EXCEPTION_FLAG:
        if len(frame) != 5:
            raise DeviceProtocolError(device, f"exception reply of {len(frame)} bytes, expected 5")
        raise ModbusExceptionError(device, function, frame[2])
    if frame[1] != function:
        raise DeviceProtocolError(device, f"reply to function {frame[1]:#04x}, expected {function:#04x}")
    if function in (READ_HOLDING, READ_INPUT):
        if len(frame) != 5 + frame[2] or frame[2] % 2:
            raise DeviceProtocolError(device, f"read reply length {len(frame)} ≠ byte count {frame[2]} + 5")
        return frame[3:-2]
    if len(frame) != 8:
        raise DeviceProtocolError(device, f"write reply of {len(frame)} bytes, expected 8")
    return frame[2:6]


# ----------------------------------------------------------------------------------------------- requests
# The device side (used by the fake): split a byte stream into requests and answer them.


@dataclass(frozen=True)
class Request:
    slave: int
    function: int
    address: int
    count: int
    data: bytes = b""  # FC16: the register bytes written


def request_length(head: bytes) -> int | None:
    """The full length of a request starting with ``head``; None if more bytes are needed or unknown."""
    if len(head) < 2:
        return None
    function = head[1]
    if function in (READ_HOLDING, READ_INPUT, 0x05, 0x06):
        return 8
    if function in (0x0F, WRITE_MULTIPLE):
        return None if len(head) < 7 else 9 + head[6]
    return None  # unknown function: the caller takes the whole burst as one frame


def parse_request(frame: bytes) -> Request | int:
    """A request, or the exception code to answer (ILLEGAL_FUNCTION / ILLEGAL_VALUE).

    The caller has already checked the CRC (a device ignores frames with a bad CRC, it never answers).
    """
    slave, function = frame[0], frame[1]
    if function in (READ_HOLDING, READ_INPUT):
        if len(frame) != 8:
            return ILLEGAL_VALUE
        address, count = int.from_bytes(frame[2:4], "big"), int.from_bytes(frame[4:6], "big")
        if not 1 <= count <= MAX_READ:
            return ILLEGAL_VALUE
        return Request(slave, function, address, count)
    if function == WRITE_MULTIPLE:
        if len(frame) < 9:
            return ILLEGAL_VALUE
        address, count = int.from_bytes(frame[2:4], "big"), int.from_bytes(frame[4:6], "big")
        data = frame[7:-2]
        if not 1 <= count <= MAX_WRITE or frame[6] != 2 * count or len(data) != 2 * count:
            return ILLEGAL_VALUE
        return Request(slave, function, address, count, data)
    return ILLEGAL_FUNCTION


def read_reply(slave: int, function: int, data: bytes) -> bytes:
    return with_crc(bytes([slave, function, len(data)]) + data)


def write_reply(slave: int, address: int, count: int) -> bytes:
    return with_crc(bytes([slave, WRITE_MULTIPLE]) + address.to_bytes(2, "big") + count.to_bytes(2, "big"))


def exception_reply(slave: int, function: int, code: int) -> bytes:
    return with_crc(bytes([slave, (function | EXCEPTION_FLAG) & 0xFF, code]))
