"""The one table of function codes: each entry names the code's own classes, and decoding
goes through it."""

from __future__ import annotations

import pytest

from aiortu.core import pdu
from aiortu.core.codes import FunctionCode
from aiortu.core.errors import MalformedPDU
from aiortu.core.pdu import (
    PDU,
    PDU_CLASSES,
    RawPDU,
    decode_request,
    decode_response,
    known_function_codes,
)


@pytest.mark.parametrize("code", sorted(PDU_CLASSES))
def test_an_entry_names_the_codes_request_and_its_reply(code: int) -> None:
    request_class, response_class = PDU_CLASSES[code]
    assert request_class.function_code == code
    assert response_class.function_code == code
    assert request_class.response_class is response_class


def test_every_public_function_code_decodes_into_a_class_of_its_own() -> None:
    assert known_function_codes() == frozenset(FunctionCode)
    assert set(PDU_CLASSES) == set(FunctionCode) - {FunctionCode.ENCAPSULATED_INTERFACE_TRANSPORT}


def test_every_request_and_response_class_is_in_the_table() -> None:
    exported = [getattr(pdu, name) for name in pdu.__all__]
    classes = {cls for cls in exported if isinstance(cls, type) and issubclass(cls, PDU)}
    in_table = {cls for pair in PDU_CLASSES.values() for cls in pair}
    # The bases, the three PDUs of no one code (a register read kept as bytes is made by
    # its caller, never decoded), and 2B's classes told apart by their MEI type.
    assert {cls.__name__ for cls in classes - in_table} == {
        "PDU",
        "Request",
        "Response",
        "ExceptionPDU",
        "RawPDU",
        "RawRegisterRead",
        "ReadDeviceIdentificationRequest",
        "ReadDeviceIdentificationResponse",
    }


@pytest.mark.parametrize("code", sorted(PDU_CLASSES))
def test_decoding_uses_the_tables_classes(code: int) -> None:
    # The function code alone: a whole request of the codes that carry no data, too short
    # for the rest, whose class's own decode then rejects it and names itself.
    request_class, response_class = PDU_CLASSES[code]
    if code in _NO_DATA:
        assert type(decode_request(bytes((code,)))) is request_class
    else:
        with pytest.raises(MalformedPDU, match=request_class.__name__):
            decode_request(bytes((code,)))
    with pytest.raises(MalformedPDU, match=response_class.__name__):
        decode_response(bytes((code,)))


_NO_DATA = {
    FunctionCode.READ_EXCEPTION_STATUS,
    FunctionCode.GET_COMM_EVENT_COUNTER,
    FunctionCode.GET_COMM_EVENT_LOG,
    FunctionCode.REPORT_SERVER_ID,
}


def test_a_code_outside_the_table_decodes_raw() -> None:
    assert decode_request(bytes((0x41, 1, 2))) == RawPDU(0x41, b"\x01\x02")
    assert decode_response(bytes((0x41,))) == RawPDU(0x41)
