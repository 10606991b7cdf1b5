"""The PDUs of read device identification (2B / MEI type 0E).

Function code 0x2B is the Encapsulated Interface Transport: its first data byte, the MEI
type, says what it carries. aiortu models MEI type 0x0E, read device identification; any
other MEI type (0x0D CANopen general reference, vendor types) decodes to
[`RawPDU`][aiortu.core.pdu.RawPDU] with function code 0x2B and the MEI type as its first
data byte, so that it reaches a user handler instead of failing. Only a 2B PDU without an
MEI type at all is malformed.

A device's identification is a list of objects, each an id (0..255) and a value (bytes,
usually ASCII text). A stream read (basic, regular, extended) may need several
transactions: while a reply says `more_follows`, ask again from `next_object_id`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Self

from aiortu.core.codes import MEI_READ_DEVICE_IDENTIFICATION, DeviceIdReadCode, FunctionCode
from aiortu.core.errors import MalformedPDU
from aiortu.core.pdu._base import (
    BYTE_RANGE,
    MAX_PDU_LENGTH,
    RawPDU,
    Request,
    Response,
)

__all__ = (
    "CONFORMITY_LEVELS",
    "ReadDeviceIdentificationRequest",
    "ReadDeviceIdentificationResponse",
    "decode_mei_request",
    "decode_mei_response",
)

CONFORMITY_LEVELS = (0x01, 0x02, 0x03, 0x81, 0x82, 0x83)
"""The conformity levels a device may report: 01 basic, 02 regular, 03 extended
identification (stream access only); 0x81..0x83 the same with individual access too."""

_READ_CODE_RANGE = range(DeviceIdReadCode.BASIC, DeviceIdReadCode.INDIVIDUAL + 1)
_HEADER_LENGTH = 7
"""Function code, MEI type, read code, conformity, more follows, next object id, count."""
_OBJECT_HEADER_LENGTH = 2
_PDU_LENGTH = range(MAX_PDU_LENGTH + 1)
_MORE_FOLLOWS = 0xFF
_NO_MORE = 0x00


def _as_read_code(value: int) -> int:
    try:
        return DeviceIdReadCode(value)
    except ValueError:
        return value


def _as_bytes(value: object) -> bytes:
    # Not bytes(value): bytes(n) would silently make n zero bytes of an int.
    if not isinstance(value, bytes | bytearray | memoryview):
        raise TypeError(f"a device id object value must be bytes, not {type(value).__name__}")
    return bytes(value)


@dataclass(frozen=True, slots=True)
class ReadDeviceIdentificationResponse(Response):
    """Reply to read device identification: some objects of the device, in the device's order.

    `read_code` echoes the request's; `conformity_level` is one of
    [`CONFORMITY_LEVELS`][aiortu.core.pdu.CONFORMITY_LEVELS]; `objects` is a tuple of
    `(object id, value)` pairs, ids 0..255 and values of bytes, as many as fit the 253-byte PDU (a
    value at most 244 bytes). When `more_follows` is true, `next_object_id` names the object to ask
    for next; the spec wants it 0 otherwise, which is not enforced because devices differ.
    """

    function_code: ClassVar[int] = FunctionCode.ENCAPSULATED_INTERFACE_TRANSPORT
    mei_type: ClassVar[int] = MEI_READ_DEVICE_IDENTIFICATION
    read_code: int
    conformity_level: int
    objects: tuple[tuple[int, bytes], ...]
    more_follows: bool = False
    next_object_id: int = 0

    def __post_init__(self) -> None:
        self._check("read_code", self.read_code, _READ_CODE_RANGE)
        object.__setattr__(self, "read_code", _as_read_code(self.read_code))
        if self.conformity_level not in CONFORMITY_LEVELS:
            raise self._invalid(
                "conformity_level", self.conformity_level, "0x01..0x03 or 0x81..0x83"
            )
        object.__setattr__(self, "more_follows", bool(self.more_follows))
        self._check("next_object_id", self.next_object_id, BYTE_RANGE)
        objects = tuple((object_id, _as_bytes(value)) for object_id, value in self.objects)
        object.__setattr__(self, "objects", objects)
        self._check("len(objects)", len(objects), BYTE_RANGE)
        for index, (object_id, value) in enumerate(objects):
            self._check(f"objects[{index}][0]", object_id, BYTE_RANGE)
            self._check(f"len(objects[{index}][1])", len(value), BYTE_RANGE)
        length = _HEADER_LENGTH + sum(_OBJECT_HEADER_LENGTH + len(value) for _, value in objects)
        self._check("len(PDU)", length, _PDU_LENGTH)

    def object_map(self) -> dict[int, bytes]:
        """The objects as a dict from id to value (a later duplicate id wins)."""
        return dict(self.objects)

    def encode(self) -> bytes:
        header = bytes(
            (
                self.function_code,
                self.mei_type,
                self.read_code,
                self.conformity_level,
                _MORE_FOLLOWS if self.more_follows else _NO_MORE,
                self.next_object_id,
                len(self.objects),
            )
        )
        return header + b"".join(
            bytes((object_id, len(value))) + value for object_id, value in self.objects
        )

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_function_code(pdu)
        cls._expect_min_length(pdu, _HEADER_LENGTH)
        _expect_mei_type(cls, pdu)
        more = pdu[4]
        if more not in (_NO_MORE, _MORE_FOLLOWS):
            raise MalformedPDU(
                cls.__name__, field="more_follows", value=more, allowed="0x00 or 0xFF"
            )
        count = pdu[6]
        objects = []
        position = _HEADER_LENGTH
        for index in range(count):
            if position + _OBJECT_HEADER_LENGTH > len(pdu):
                raise MalformedPDU(
                    f"{cls.__name__}: PDU ends before object {index}",
                    field="number_of_objects",
                    value=count,
                    allowed=range(index + 1),
                )
            object_id, length = pdu[position], pdu[position + 1]
            start = position + _OBJECT_HEADER_LENGTH
            if start + length > len(pdu):
                raise MalformedPDU(
                    f"{cls.__name__}: object value runs past the PDU",
                    field=f"len(objects[{index}][1])",
                    value=length,
                    allowed=range(len(pdu) - start + 1),
                )
            objects.append((object_id, bytes(pdu[start : start + length])))
            position = start + length
        cls._expect_length(pdu, position)
        return cls._build(
            lambda: cls(pdu[2], pdu[3], tuple(objects), more == _MORE_FOLLOWS, pdu[5])
        )


@dataclass(frozen=True, slots=True)
class ReadDeviceIdentificationRequest(Request):
    """Read the identification of a device: `read_code` (1..4) from `object_id` (0..255).

    Read codes 1..3 (basic, regular, extended) stream the objects of that category from
    `object_id` on, 0 to start; read code 4 (individual) reads the one object `object_id`.
    Whether an object id exists is the device's business (it answers exception 02), so any
    0..255 is accepted here.
    """

    function_code: ClassVar[int] = FunctionCode.ENCAPSULATED_INTERFACE_TRANSPORT
    response_class: ClassVar[type[Response]] = ReadDeviceIdentificationResponse
    mei_type: ClassVar[int] = MEI_READ_DEVICE_IDENTIFICATION
    read_code: int = DeviceIdReadCode.BASIC
    object_id: int = 0

    def __post_init__(self) -> None:
        self._check("read_code", self.read_code, _READ_CODE_RANGE)
        object.__setattr__(self, "read_code", _as_read_code(self.read_code))
        self._check("object_id", self.object_id, BYTE_RANGE)

    def encode(self) -> bytes:
        return bytes((self.function_code, self.mei_type, self.read_code, self.object_id))

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_function_code(pdu)
        cls._expect_length(pdu, 4)
        _expect_mei_type(cls, pdu)
        return cls._build(lambda: cls(pdu[2], pdu[3]))

    def check_response(self, response: Response) -> None:
        Request.check_response(self, response)
        assert isinstance(response, ReadDeviceIdentificationResponse)
        if response.read_code != self.read_code:
            raise MalformedPDU(
                "reply read device id code differs from the request's",
                field="read_code",
                value=response.read_code,
                allowed=range(self.read_code, self.read_code + 1),
            )
        if self.read_code == DeviceIdReadCode.INDIVIDUAL:
            ids = tuple(object_id for object_id, _ in response.objects)
            if ids != (self.object_id,):
                raise MalformedPDU(
                    "an individual read must return exactly the object asked for",
                    field="objects ids",
                    value=ids,
                    allowed=(self.object_id,),
                )


def _expect_mei_type(cls: type[Request] | type[Response], pdu: bytes) -> None:
    if pdu[1] != MEI_READ_DEVICE_IDENTIFICATION:
        raise MalformedPDU(
            cls.__name__,
            field="mei_type",
            value=pdu[1],
            allowed=range(MEI_READ_DEVICE_IDENTIFICATION, MEI_READ_DEVICE_IDENTIFICATION + 1),
        )


def _expect_mei_byte(pdu: bytes) -> None:
    if len(pdu) < 2:
        raise MalformedPDU(
            "encapsulated interface transport without an MEI type",
            field="length",
            value=len(pdu),
            allowed=range(2, MAX_PDU_LENGTH + 1),
        )


def decode_mei_request(pdu: bytes) -> Request:
    """Decode a 2B request: read device identification for MEI type 0x0E, else RawPDU."""
    _expect_mei_byte(pdu)
    if pdu[1] == MEI_READ_DEVICE_IDENTIFICATION:
        return ReadDeviceIdentificationRequest.decode(pdu)
    return RawPDU.decode(pdu)


def decode_mei_response(pdu: bytes) -> Response:
    """Decode a 2B reply: read device identification for MEI type 0x0E, else RawPDU."""
    _expect_mei_byte(pdu)
    if pdu[1] == MEI_READ_DEVICE_IDENTIFICATION:
        return ReadDeviceIdentificationResponse.decode(pdu)
    return RawPDU.decode(pdu)
