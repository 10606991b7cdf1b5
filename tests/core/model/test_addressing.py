"""The four tables, references in 5- and 6-digit notation, and address conversions."""

from __future__ import annotations

import dataclasses

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiortu.core.errors import InvalidValue
from aiortu.core.model import (
    Reference,
    Table,
    data_model_number,
    format_reference,
    parse_reference,
    protocol_address,
)


def test_table_properties() -> None:
    assert [table.prefix for table in Table] == [0, 1, 3, 4]
    assert [table.is_bit for table in Table] == [True, True, False, False]
    assert [table.writable for table in Table] == [True, False, False, True]
    for table in Table:
        assert Table.from_prefix(table.prefix) is table


@pytest.mark.parametrize("prefix", [2, 5, 9, -1])
def test_no_table_for_prefix(prefix: int) -> None:
    with pytest.raises(InvalidValue) as caught:
        Table.from_prefix(prefix)
    assert caught.value.field == "prefix"


def test_example_from_the_notes() -> None:
    reference = parse_reference("40108")
    assert reference == Reference(Table.HOLDING_REGISTERS, 107)
    assert reference.number == 108
    assert format_reference(reference, 6) == "400108"
    assert format_reference(reference) == "40108"
    assert parse_reference("400108") == reference
    assert str(reference) == "400108"


@pytest.mark.parametrize(
    ("text", "table", "address"),
    [
        ("1", Table.COILS, 0),
        ("9999", Table.COILS, 9998),
        ("00001", Table.COILS, 0),
        ("09999", Table.COILS, 9998),
        ("0001", Table.COILS, 0),
        ("10001", Table.DISCRETE_INPUTS, 0),
        ("19999", Table.DISCRETE_INPUTS, 9998),
        ("30001", Table.INPUT_REGISTERS, 0),
        ("40001", Table.HOLDING_REGISTERS, 0),
        ("49999", Table.HOLDING_REGISTERS, 9998),
        ("000001", Table.COILS, 0),
        ("065536", Table.COILS, 65535),
        ("100001", Table.DISCRETE_INPUTS, 0),
        ("165536", Table.DISCRETE_INPUTS, 65535),
        ("300001", Table.INPUT_REGISTERS, 0),
        ("400001", Table.HOLDING_REGISTERS, 0),
        ("465536", Table.HOLDING_REGISTERS, 65535),
        (" 40108\n", Table.HOLDING_REGISTERS, 107),
    ],
)
def test_parse(text: str, table: Table, address: int) -> None:
    assert parse_reference(text) == Reference(table, address)


def test_six_digit_coils_need_the_leading_zero() -> None:
    # Without it, "100001" is a discrete input, never coil 100001.
    assert parse_reference("100001").table is Table.DISCRETE_INPUTS
    assert parse_reference("010001") == Reference(Table.COILS, 10000)


@pytest.mark.parametrize(
    "text",
    [
        "",
        " ",
        "abc",
        "4O001",
        "-1",
        "+1",
        "1.5",
        "1_000",
        "4 0001",
        "0x10",
        "\u0664\u0660\u0660\u0660\u0661",  # Arabic-Indic digits: isdigit() but not a reference
        "\u00b9",  # superscript one
        "1234567",
        "0000000",
        "20001",
        "200001",
        "50001",
        "900001",
        "0",
        "0000",
        "00000",
        "000000",
        "10000",
        "30000",
        "40000",
        "400000",
        "300000",
        "065537",
        "165537",
        "365537",
        "465537",
        "499999",
    ],
)
def test_rejected(text: str) -> None:
    with pytest.raises(InvalidValue) as caught:
        parse_reference(text)
    assert caught.value.field == "reference"
    assert caught.value.value == text


def test_zero_number_message_helps() -> None:
    with pytest.raises(InvalidValue, match="40001"):
        parse_reference("40000")
    with pytest.raises(InvalidValue, match="400001"):
        parse_reference("400000")


def test_rejects_non_strings() -> None:
    with pytest.raises(InvalidValue) as caught:
        parse_reference(40001)  # type: ignore[arg-type]
    assert caught.value.field == "reference"


@given(st.sampled_from(Table), st.integers(0, 0xFFFF))
def test_six_digit_round_trip(table: Table, address: int) -> None:
    reference = Reference(table, address)
    text = format_reference(reference, 6)
    assert len(text) == 6
    assert text[0] == str(table.prefix)
    assert int(text[1:]) == address + 1
    assert parse_reference(text) == reference


@given(st.sampled_from(Table), st.integers(0, 9998))
def test_five_digit_round_trip(table: Table, address: int) -> None:
    reference = Reference(table, address)
    text = format_reference(reference, 5)
    assert len(text) == 5
    assert parse_reference(text) == reference
    if table is Table.COILS:
        assert parse_reference(text.lstrip("0")) == reference


@given(st.sampled_from(Table), st.integers(9999, 0xFFFF))
def test_five_digits_cannot_hold_large_numbers(table: Table, address: int) -> None:
    with pytest.raises(InvalidValue) as caught:
        format_reference(Reference(table, address), 5)
    assert caught.value.field == "number"
    assert caught.value.value == address + 1


@pytest.mark.parametrize("digits", [4, 7, 0])
def test_format_digits(digits: int) -> None:
    with pytest.raises(InvalidValue) as caught:
        format_reference(Reference(Table.COILS, 0), digits)
    assert caught.value.field == "digits"


@pytest.mark.parametrize("address", [-1, 0x10000, 1.0, True, "1"])
def test_reference_address_checked(address: object) -> None:
    with pytest.raises(InvalidValue) as caught:
        Reference(Table.COILS, address)  # type: ignore[arg-type]
    assert caught.value.field == "address"


def test_reference_table_checked() -> None:
    with pytest.raises(InvalidValue) as caught:
        Reference("registers", 0)  # type: ignore[arg-type]
    assert caught.value.field == "table"


def test_reference_table_by_value() -> None:
    reference = Reference("coils", 3)  # type: ignore[arg-type]
    assert reference.table is Table.COILS
    assert reference == Reference(Table.COILS, 3)


def test_reference_is_frozen_and_hashable() -> None:
    reference = Reference(Table.COILS, 5)
    with pytest.raises(dataclasses.FrozenInstanceError):
        reference.address = 6  # type: ignore[misc]
    assert {reference: 1}[Reference(Table.COILS, 5)] == 1
    assert Reference.from_number(Table.COILS, 6) == reference


def test_number_conversions() -> None:
    assert protocol_address(1) == 0
    assert protocol_address(65536) == 65535
    assert data_model_number(0) == 1
    assert data_model_number(65535) == 65536


@given(st.integers(0, 0xFFFF))
def test_number_round_trip(address: int) -> None:
    assert protocol_address(data_model_number(address)) == address


@pytest.mark.parametrize("number", [0, 65537, -5, 2.0])
def test_protocol_address_rejects(number: object) -> None:
    with pytest.raises(InvalidValue) as caught:
        protocol_address(number)  # type: ignore[arg-type]
    assert caught.value.field == "number"


@pytest.mark.parametrize("address", [-1, 65536, 0.5])
def test_data_model_number_rejects(address: object) -> None:
    with pytest.raises(InvalidValue) as caught:
        data_model_number(address)  # type: ignore[arg-type]
    assert caught.value.field == "address"
