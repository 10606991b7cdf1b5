"""The PDUs of read device identification (2B / MEI 0E), and other MEI types as RawPDU."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiortu.core.codes import DeviceIdObject, DeviceIdReadCode
from aiortu.core.errors import InvalidRequest, InvalidValue, MalformedPDU
from aiortu.core.pdu import (
    RawPDU,
    ReadDeviceIdentificationRequest,
    ReadDeviceIdentificationResponse,
    decode_request,
    decode_response,
    known_function_codes,
)
from aiortu.core.pdu import _device_id as di
from tests.core.pdu_contract import assert_invalid, assert_only_malformed, assert_round_trip
from tests.core.strategies_serial_files_devid import (
    REQUEST_STRATEGIES,
    RESPONSE_STRATEGIES,
    mutations,
)

Req = ReadDeviceIdentificationRequest
Resp = ReadDeviceIdentificationResponse

SPEC_OBJECTS = (
    (DeviceIdObject.VENDOR_NAME, b"Company identification"),
    (DeviceIdObject.PRODUCT_CODE, b"Product code XX"),
    (DeviceIdObject.MAJOR_MINOR_REVISION, b"V2.11"),
)
SPEC_REPLY = Resp(DeviceIdReadCode.BASIC, 0x01, SPEC_OBJECTS)
SPEC_REPLY_WIRE = (
    bytes.fromhex("2B 0E 01 01 00 00 03")
    + b"\x00\x16Company identification"
    + b"\x01\x0fProduct code XX"
    + b"\x02\x05V2.11"
)


def test_public_names() -> None:
    assert isinstance(di.__all__, tuple)
    assert all(hasattr(di, name) for name in di.__all__)
    assert 0x2B in known_function_codes()


@given(request=REQUEST_STRATEGIES[Req])
def test_request_round_trip(request: Req) -> None:
    assert_round_trip(request)


@given(response=RESPONSE_STRATEGIES[Resp])
def test_response_round_trip(response: Resp) -> None:
    assert_round_trip(response)


def test_basic_request_vector() -> None:
    request = Req()
    assert request.encode() == bytes.fromhex("2B 0E 01 00")
    assert decode_request(bytes.fromhex("2B 0E 01 00")) == request
    individual = Req(DeviceIdReadCode.INDIVIDUAL, 0x05)
    assert individual.encode() == bytes.fromhex("2B 0E 04 05")
    assert decode_request(individual.encode()) == individual


def test_spec_reply_vector() -> None:
    assert SPEC_REPLY.encode() == SPEC_REPLY_WIRE
    assert decode_response(SPEC_REPLY_WIRE) == SPEC_REPLY
    assert SPEC_REPLY.object_map()[DeviceIdObject.MAJOR_MINOR_REVISION] == b"V2.11"
    Req().check_response(SPEC_REPLY)


def test_more_follows_vector() -> None:
    reply = Resp(DeviceIdReadCode.REGULAR, 0x82, ((3, b"x"),), more_follows=True, next_object_id=4)
    assert reply.encode() == bytes.fromhex("2B 0E 02 82 FF 04 01 03 01 78")
    assert_round_trip(reply)


def test_decoded_codes_are_enums() -> None:
    decoded = decode_request(bytes.fromhex("2B 0E 03 80"))
    assert isinstance(decoded, Req)
    assert decoded.read_code is DeviceIdReadCode.EXTENDED


def test_objects_keep_order_and_duplicates() -> None:
    objects = ((5, b"e"), (1, b"a"), (5, b""))
    reply = Resp(DeviceIdReadCode.EXTENDED, 0x83, objects)
    decoded = decode_response(reply.encode())
    assert isinstance(decoded, Resp)
    assert decoded.objects == objects
    assert decoded.object_map() == {5: b"", 1: b"a"}


# Other MEI types travel as RawPDU.


@pytest.mark.parametrize("wire", ["2B 0D 00 01 02", "2B 0D", "2B 00", "2B FF 01 02 03"])
def test_other_mei_types_are_raw(wire: str) -> None:
    data = bytes.fromhex(wire)
    for decode in (decode_request, decode_response):
        decoded = decode(data)
        assert decoded == RawPDU(0x2B, data[1:])
        assert decoded.encode() == data
    request = decode_request(data)
    assert isinstance(request, RawPDU)
    request.check_response(RawPDU(0x2B, b"\x0d\x99"))


def test_2b_without_mei_type_is_malformed() -> None:
    for decode in (decode_request, decode_response):
        with pytest.raises(MalformedPDU) as caught:
            decode(b"\x2b")
        assert caught.value.field == "length"


# Construction rejects every field out of range.


@pytest.mark.parametrize(
    ("build", "error", "field", "value", "allowed"),
    [
        (lambda: Req(0), InvalidRequest, "read_code", 0, range(1, 5)),
        (lambda: Req(5), InvalidRequest, "read_code", 5, range(1, 5)),
        (lambda: Req(1, 256), InvalidRequest, "object_id", 256, range(256)),
        (lambda: Req(4, -1), InvalidRequest, "object_id", -1, range(256)),
        (lambda: Resp(0, 1, ()), InvalidValue, "read_code", 0, range(1, 5)),
        (lambda: Resp(1, 0x04, ()), InvalidValue, "conformity_level", 4, None),
        (lambda: Resp(1, 0x80, ()), InvalidValue, "conformity_level", 0x80, None),
        (lambda: Resp(1, 1, (), True, 256), InvalidValue, "next_object_id", 256, range(256)),
        (lambda: Resp(1, 1, ((256, b""),)), InvalidValue, "objects[0][0]", 256, range(256)),
        (
            lambda: Resp(1, 1, ((1, b""), (2, bytes(256)))),
            InvalidValue,
            "len(objects[1][1])",
            256,
            range(256),
        ),
        (lambda: Resp(1, 1, ((0, b""),) * 256), InvalidValue, "len(objects)", 256, range(256)),
        (lambda: Resp(1, 1, ((0, bytes(245)),)), InvalidValue, "len(PDU)", 254, range(254)),
        (
            lambda: Resp(1, 1, ((0, bytes(100)), (1, bytes(143)))),
            InvalidValue,
            "len(PDU)",
            254,
            range(254),
        ),
    ],
)
def test_fields_out_of_range(
    build: Any, error: type[InvalidValue], field: str, value: object, allowed: object
) -> None:
    assert_invalid(build, error, field, value, allowed)


def test_largest_object_fits() -> None:
    assert len(Resp(1, 1, ((0, bytes(244)),)).encode()) == 253


def test_object_value_must_be_bytes() -> None:
    with pytest.raises(TypeError):
        Resp(1, 1, ((0, 3),))  # type: ignore[arg-type]


# Decoding: wrong bytes give MalformedPDU and nothing else.


@pytest.mark.parametrize(
    ("decode", "wire", "field"),
    [
        (decode_request, "2B 0E 01", "length"),
        (decode_request, "2B 0E 01 00 00", "length"),
        (decode_request, "2B 0E 00 00", "read_code"),
        (decode_request, "2B 0E 05 00", "read_code"),
        (decode_response, "2B 0E 01 01 00 00", "length"),
        (decode_response, "2B 0E 01 01 01 00 00", "more_follows"),
        (decode_response, "2B 0E 01 04 00 00 00", "conformity_level"),
        (decode_response, "2B 0E 00 01 00 00 00", "read_code"),
        (decode_response, "2B 0E 01 01 00 00 01", "number_of_objects"),
        (decode_response, "2B 0E 01 01 00 00 02 00 00 01", "number_of_objects"),
        (decode_response, "2B 0E 01 01 00 00 01 00 02 41", "len(objects[0][1])"),
        (decode_response, "2B 0E 01 01 00 00 01 00 01 41 42", "length"),
        (decode_response, "2B 0E 01 01 00 00 00 00", "length"),
    ],
    ids=str,
)
def test_malformed_vectors(decode: Any, wire: str, field: str) -> None:
    with pytest.raises(MalformedPDU) as caught:
        decode(bytes.fromhex(wire))
    assert caught.value.field == field
    assert caught.value.exception_code == 3


def test_class_decode_checks_the_mei_type() -> None:
    for cls, wire in ((Req, "2B 0D 01 00"), (Resp, "2B 0D 01 01 00 00 00")):
        with pytest.raises(MalformedPDU) as caught:
            cls.decode(bytes.fromhex(wire))
        assert caught.value.field == "mei_type"


encoded = st.one_of(REQUEST_STRATEGIES[Req], RESPONSE_STRATEGIES[Resp]).map(
    lambda pdu: pdu.encode()
)


@given(mei=st.sampled_from((0x0E, 0x0E, 0x0D, 0x00)), body=st.binary(max_size=260))
def test_arbitrary_bytes_only_malformed(mei: int, body: bytes) -> None:
    data = bytes((0x2B, mei)) + body
    assert_only_malformed(decode_request, data)
    assert_only_malformed(decode_response, data)
    assert_only_malformed(Req.decode, data)
    assert_only_malformed(Resp.decode, data)


@given(data=mutations(encoded))
def test_mutations_only_malformed(data: bytes) -> None:
    assert_only_malformed(decode_request, data)
    assert_only_malformed(decode_response, data)


# check_response


@given(request=REQUEST_STRATEGIES[Req], response=RESPONSE_STRATEGIES[Resp])
def test_check_response_matches_the_rules(request: Req, response: Resp) -> None:
    ids = tuple(object_id for object_id, _ in response.objects)
    if response.read_code != request.read_code:
        expected: str | None = "read_code"
    elif request.read_code == DeviceIdReadCode.INDIVIDUAL and ids != (request.object_id,):
        expected = "objects ids"
    else:
        expected = None
    if expected is None:
        request.check_response(response)
    else:
        with pytest.raises(MalformedPDU) as caught:
            request.check_response(response)
        assert caught.value.field == expected


@pytest.mark.parametrize(
    ("request_", "response"),
    [
        (Req(DeviceIdReadCode.INDIVIDUAL, 4), Resp(4, 0x83, ((4, b"Pump"),))),
        (Req(DeviceIdReadCode.REGULAR, 9), Resp(2, 0x02, ((0, b"a"),), True, 1)),
        (Req(DeviceIdReadCode.EXTENDED), Resp(3, 0x03, ())),
    ],
)
def test_check_response_passes(request_: Req, response: Resp) -> None:
    request_.check_response(response)


@pytest.mark.parametrize(
    ("request_", "response", "field"),
    [
        (Req(DeviceIdReadCode.BASIC), Resp(2, 0x01, SPEC_OBJECTS), "read_code"),
        (Req(DeviceIdReadCode.INDIVIDUAL, 4), Resp(1, 0x81, ((4, b"x"),)), "read_code"),
        (Req(DeviceIdReadCode.INDIVIDUAL, 4), Resp(4, 0x81, ((5, b"x"),)), "objects ids"),
        (Req(DeviceIdReadCode.INDIVIDUAL, 4), Resp(4, 0x81, ()), "objects ids"),
        (
            Req(DeviceIdReadCode.INDIVIDUAL, 4),
            Resp(4, 0x81, ((4, b"x"), (5, b"y"))),
            "objects ids",
        ),
        (Req(), RawPDU(0x2B, b"\x0e"), None),
    ],
)
def test_check_response_mismatch(request_: Req, response: Any, field: str | None) -> None:
    with pytest.raises(MalformedPDU) as caught:
        request_.check_response(response)
    assert caught.value.field == field
