"""The four data tables and the vendor notations for their elements.

On the wire every table is addressed 0..65535 (the *protocol address*). Manuals number the
elements from 1 instead (the *data-model number*: element n has protocol address n - 1), and
many write them as one reference that also names the table by its leading digit:

========================  ============  =============
table                     5-digit       6-digit
========================  ============  =============
coils                     00001-09999   000001-065536
discrete inputs           10001-19999   100001-165536
input registers           30001-39999   300001-365536
holding registers         40001-49999   400001-465536
========================  ============  =============

A 5-digit coil reference may drop its leading zeros ("1" is coil 1), but a 6-digit one
keeps them: "000001" is coil 1, while "100001" is discrete input 1. So the number of digits
decides the form, and only six digits reach numbers above 9999:

    >>> ref = parse_reference("40108")
    >>> ref.table, ref.address, ref.number
    (<Table.HOLDING_REGISTERS: 'holding_registers'>, 107, 108)
    >>> format_reference(ref, 6)
    '400108'
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from aiortu.core.errors import InvalidValue

__all__ = (
    "ADDRESS_RANGE",
    "NUMBER_RANGE",
    "Reference",
    "Table",
    "data_model_number",
    "format_reference",
    "parse_reference",
    "protocol_address",
)

ADDRESS_RANGE = range(0x10000)
"""Protocol addresses of every table: 0..65535."""

NUMBER_RANGE = range(1, 0x10001)
"""Data-model numbers of every table: 1..65536."""

_FIVE_DIGIT_NUMBERS = range(1, 10000)
"""The numbers a 5-digit reference can hold: four digits after the table prefix."""


class Table(enum.StrEnum):
    """One of the four tables of the Modbus data model."""

    COILS = "coils"
    DISCRETE_INPUTS = "discrete_inputs"
    INPUT_REGISTERS = "input_registers"
    HOLDING_REGISTERS = "holding_registers"

    @property
    def is_bit(self) -> bool:
        """Whether the elements are single bits (coils, discrete inputs), not 16-bit registers."""
        return self in (Table.COILS, Table.DISCRETE_INPUTS)

    @property
    def writable(self) -> bool:
        """Whether a master may write it (coils and holding registers)."""
        return self in (Table.COILS, Table.HOLDING_REGISTERS)

    @property
    def prefix(self) -> int:
        """The leading digit of the table's 5- and 6-digit references: 0, 1, 3 or 4."""
        return _PREFIXES[self]

    @classmethod
    def from_prefix(cls, prefix: int) -> Table:
        """The table whose references start with `prefix`; InvalidValue for 2 and 5..9."""
        for table, digit in _PREFIXES.items():
            if digit == prefix:
                return table
        raise InvalidValue("prefix", prefix, "0, 1, 3 or 4")


_PREFIXES: dict[Table, int] = {
    Table.COILS: 0,
    Table.DISCRETE_INPUTS: 1,
    Table.INPUT_REGISTERS: 3,
    Table.HOLDING_REGISTERS: 4,
}


def _check_int(field: str, value: object, allowed: range) -> None:
    # `in range` alone would accept 5.0 (and scan the range to do it) and True.
    if not isinstance(value, int) or isinstance(value, bool) or value not in allowed:
        raise InvalidValue(field, value, allowed)


def protocol_address(number: int) -> int:
    """The protocol address (0..65535) of data-model number `number` (1..65536)."""
    _check_int("number", number, NUMBER_RANGE)
    return number - 1


def data_model_number(address: int) -> int:
    """The data-model number (1..65536) of protocol address `address` (0..65535)."""
    _check_int("address", address, ADDRESS_RANGE)
    return address + 1


@dataclass(frozen=True, slots=True)
class Reference:
    """One element of one table: `table` and its protocol `address` (0..65535).

    `table` may also be given by its value (`"holding_registers"`); it is stored as a
    [`Table`][aiortu.core.model.Table].
    """

    table: Table
    address: int

    def __post_init__(self) -> None:
        # Coerce by value, so that the table names as strings ("coils") and any other
        # enum with the same values work as well.
        try:
            object.__setattr__(self, "table", Table(self.table))
        except ValueError:
            raise InvalidValue("table", self.table, ", ".join(Table)) from None
        _check_int("address", self.address, ADDRESS_RANGE)

    @classmethod
    def from_number(cls, table: Table, number: int) -> Reference:
        """The element of `table` with data-model number `number` (1..65536)."""
        return cls(table, protocol_address(number))

    @property
    def number(self) -> int:
        """The 1-based data-model number, as manuals count: `address + 1`."""
        return self.address + 1

    def __str__(self) -> str:
        return format_reference(self, 6)


def _describe_forms() -> str:
    five = ", ".join(f"{t.prefix}0001-{t.prefix}9999" for t in Table)
    six = ", ".join(f"{t.prefix}00001-{t.prefix}65536" for t in Table)
    return f"a 5-digit reference ({five}; coils may drop leading zeros) or a 6-digit one ({six})"


def parse_reference(text: str) -> Reference:
    """Parse a 5- or 6-digit reference such as `"40108"` or `"400108"`.

    One to four digits are a 5-digit coil reference without its leading zeros, five digits
    a 5-digit reference (numbers 1..9999), six digits a 6-digit one (numbers 1..65536);
    the first of five or six digits names the table (0, 1, 3 or 4). Surrounding whitespace
    is ignored. Anything else, a number 0 (`"40000"`, `"400000"`) or a number beyond the
    form's range raises [`InvalidValue`][aiortu.errors.InvalidValue] with field `"reference"`.
    """
    if not isinstance(text, str):
        raise InvalidValue("reference", text, _describe_forms(), "a reference is a string")
    digits = text.strip()
    # isdigit() alone would let through other scripts' digits and superscripts.
    if not (digits.isascii() and digits.isdigit()) or len(digits) > 6:
        raise InvalidValue("reference", text, _describe_forms(), "not a reference")
    if len(digits) <= 4:
        table = Table.COILS
        number = int(digits)
        numbers = _FIVE_DIGIT_NUMBERS
    else:
        prefix = int(digits[0])
        if prefix not in _PREFIXES.values():
            raise InvalidValue(
                "reference", text, _describe_forms(), f"no table has the prefix {prefix}"
            )
        table = Table.from_prefix(prefix)
        number = int(digits[1:])
        numbers = _FIVE_DIGIT_NUMBERS if len(digits) == 5 else NUMBER_RANGE
    if number not in numbers:
        width = len(digits) - 1 if len(digits) > 4 else 4
        first = f"{table.prefix}{numbers.start:0{width}d}"
        last = f"{table.prefix}{numbers.stop - 1:0{width}d}"
        if number == 0:
            detail = f"numbers start at 1; protocol address 0 is {first}"
        else:
            detail = f"a table has {len(NUMBER_RANGE)} elements"
        raise InvalidValue("reference", text, f"{first}..{last}", detail)
    return Reference(table, number - 1)


def format_reference(reference: Reference, digits: int = 5) -> str:
    """Write `reference` in the 5- or 6-digit notation, leading zeros included.

    Only data-model numbers 1..9999 have a 5-digit form; for the others InvalidValue
    (field `"number"`) says to use six digits.
    """
    if digits == 5:
        if reference.number not in _FIVE_DIGIT_NUMBERS:
            raise InvalidValue(
                "number",
                reference.number,
                _FIVE_DIGIT_NUMBERS,
                "a 5-digit reference holds numbers up to 9999; use digits=6",
            )
        return f"{reference.table.prefix}{reference.number:04d}"
    if digits == 6:
        return f"{reference.table.prefix}{reference.number:05d}"
    raise InvalidValue("digits", digits, "5 or 6")
