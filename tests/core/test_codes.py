"""The spec's numbers: function codes, exception codes, and the ranges left to users."""

from __future__ import annotations

from aiortu.core.codes import (
    MBAP_UNIT_IDS,
    SERIAL_UNIT_IDS,
    USER_DEFINED_FUNCTION_CODES,
    DeviceIdObject,
    ExceptionCode,
    FunctionCode,
    is_user_defined,
)
from aiortu.core.model import OBJECT_IDS


def test_user_defined_codes_are_65_to_72_and_100_to_110() -> None:
    assert list(USER_DEFINED_FUNCTION_CODES) == [*range(65, 73), *range(100, 111)]
    assert [code for code in range(256) if is_user_defined(code)] == list(
        USER_DEFINED_FUNCTION_CODES
    )


def test_function_codes_are_the_specs() -> None:
    # Modbus Application Protocol V1.1b3, section 6 (the public codes a serial line carries).
    assert {code.name: code.value for code in FunctionCode} == {
        "READ_COILS": 0x01,
        "READ_DISCRETE_INPUTS": 0x02,
        "READ_HOLDING_REGISTERS": 0x03,
        "READ_INPUT_REGISTERS": 0x04,
        "WRITE_SINGLE_COIL": 0x05,
        "WRITE_SINGLE_REGISTER": 0x06,
        "READ_EXCEPTION_STATUS": 0x07,
        "DIAGNOSTICS": 0x08,
        "GET_COMM_EVENT_COUNTER": 0x0B,
        "GET_COMM_EVENT_LOG": 0x0C,
        "WRITE_MULTIPLE_COILS": 0x0F,
        "WRITE_MULTIPLE_REGISTERS": 0x10,
        "REPORT_SERVER_ID": 0x11,
        "READ_FILE_RECORD": 0x14,
        "WRITE_FILE_RECORD": 0x15,
        "MASK_WRITE_REGISTER": 0x16,
        "READ_WRITE_MULTIPLE_REGISTERS": 0x17,
        "READ_FIFO_QUEUE": 0x18,
        "ENCAPSULATED_INTERFACE_TRANSPORT": 0x2B,
    }


def test_exception_codes_are_the_specs() -> None:
    # Section 7 lists 01 to 06, 08, 0A and 0B.
    assert {code.name: code.value for code in ExceptionCode} == {
        "ILLEGAL_FUNCTION": 0x01,
        "ILLEGAL_DATA_ADDRESS": 0x02,
        "ILLEGAL_DATA_VALUE": 0x03,
        "SERVER_DEVICE_FAILURE": 0x04,
        "ACKNOWLEDGE": 0x05,
        "SERVER_DEVICE_BUSY": 0x06,
        "MEMORY_PARITY_ERROR": 0x08,
        "GATEWAY_PATH_UNAVAILABLE": 0x0A,
        "GATEWAY_TARGET_DEVICE_FAILED_TO_RESPOND": 0x0B,
    }


def test_device_identification_objects_are_the_specs() -> None:
    # Modbus Application Protocol V1.1b3, 6.21: the basic and regular objects 0x00..0x06.
    spec = {
        "vendor_name": 0x00,
        "product_code": 0x01,
        "revision": 0x02,
        "vendor_url": 0x03,
        "product_name": 0x04,
        "model_name": 0x05,
        "user_application_name": 0x06,
    }
    assert [int(member) for member in DeviceIdObject] == list(spec.values())
    assert dict(OBJECT_IDS) == spec  # the names a profile's [device.identify] may use


def test_the_unit_ids_of_each_framing() -> None:
    assert (SERIAL_UNIT_IDS.ids, SERIAL_UNIT_IDS.broadcast) == (range(248), 0)
    assert SERIAL_UNIT_IDS.unicast == range(1, 248)
    assert (MBAP_UNIT_IDS.ids, MBAP_UNIT_IDS.broadcast) == (range(256), None)
    assert MBAP_UNIT_IDS.unicast == range(256)
