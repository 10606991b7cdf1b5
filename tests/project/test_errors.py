"""The error hierarchy: who caused what, and what the messages say."""

from __future__ import annotations

import pytest

import aiortu
from aiortu import errors
from aiortu.core.codes import ExceptionCode
from aiortu.errors import InvalidValue


def test_every_error_is_a_modbus_error() -> None:
    for name in errors.__all__:
        error_class = getattr(errors, name)
        assert issubclass(error_class, errors.ModbusError), name


def test_the_tree_in_the_docstring_names_every_error() -> None:
    assert errors.__doc__ is not None
    for name in errors.__all__:
        assert f" {name} " in errors.__doc__, name


def test_each_error_says_who_causes_it() -> None:
    for name in errors.__all__:
        doc = getattr(errors, name).__doc__ or ""
        if name in {"ModbusError"}:
            continue
        if issubclass(getattr(errors, name), errors.PortError) and name != "PortError":
            continue  # the subclasses inherit "Caused by the environment" from PortError
        assert "Caused by" in doc, name


def test_invalid_value_names_field_value_and_range() -> None:
    error = errors.InvalidRequest("count", 126, range(1, 126))
    assert (error.field, error.value, error.allowed) == ("count", 126, range(1, 126))
    assert str(error) == "count = 126 is outside the allowed range 1..125"
    assert isinstance(error, ValueError)
    assert isinstance(error, errors.InvalidValue)


def test_exception_response_is_an_inspectable_value() -> None:
    error = errors.ExceptionResponse(2, function_code=0x01, unit=1)
    assert error.code is ExceptionCode.ILLEGAL_DATA_ADDRESS
    assert (error.function_code, error.unit) == (1, 1)
    assert "ILLEGAL_DATA_ADDRESS" in str(error)
    assert "unit 1" in str(error)
    unknown = errors.ExceptionResponse(0x42)
    assert unknown.code == 0x42
    assert "0x42" in str(unknown)


def test_timeouts_are_timeout_errors() -> None:
    with pytest.raises(TimeoutError):
        raise errors.ResponseTimeout("no reply from unit 3 within 1.0 s")


def test_crc_error_message_and_reason() -> None:
    error = errors.CRCError(0x1234, 0x8776)
    assert error.reason == "crc"
    assert "0x1234" in str(error)
    assert "0x8776" in str(error)
    assert isinstance(error, errors.FrameError)


def test_malformed_pdu_carries_the_exception_a_slave_answers() -> None:
    error = errors.MalformedPDU("bad", field="count", value=0, allowed=range(1, 126))
    assert error.exception_code == 3
    assert "count = 0" in str(error)


def test_port_errors_name_the_port() -> None:
    error = errors.PortBusy("/dev/ttyUSB0", "another program has it open")
    assert error.port == "/dev/ttyUSB0"
    assert str(error).startswith("/dev/ttyUSB0: ")


def test_the_package_reexports_the_errors_users_catch() -> None:
    for name in (
        "ModbusError",
        "ExceptionResponse",
        "ResponseTimeout",
        "FrameError",
        "ConnectionLost",
        "InvalidRequest",
    ):
        assert getattr(aiortu, name) is getattr(errors, name)


def test_a_value_not_in_a_range_says_what_is_allowed_in_words() -> None:
    error = InvalidValue("port", "tcp://x", "a serial device path")
    assert str(error) == "port must be a serial device path, not 'tcp://x'"


def test_a_value_error_may_carry_its_own_sentence() -> None:
    error = InvalidValue("coils", 3, "blocks", message="coils: the block at 3..4 overlaps")
    assert str(error) == "coils: the block at 3..4 overlaps"
    assert (error.field, error.value, error.allowed) == ("coils", 3, "blocks")


def test_a_value_errors_detail_is_kept_apart_from_its_sentence() -> None:
    error = InvalidValue("unit", 0, range(1, 248), "0 is the broadcast address")
    assert error.detail == "0 is the broadcast address"
    assert str(error).endswith(": 0 is the broadcast address")
    assert InvalidValue("unit", 0, range(1, 248)).detail == ""
