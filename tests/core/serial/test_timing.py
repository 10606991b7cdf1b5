"""Serial timing: exact figures at the common baud rates and character formats."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiortu.core.serial import FIXED_T1_5, FIXED_T3_5, LineSettings, Parity
from aiortu.errors import InvalidValue

# (baudrate, parity, stopbits) -> bits per character
FORMATS = {
    "8N1": (Parity.NONE, 1, 10),
    "8E1": (Parity.EVEN, 1, 11),
    "8N2": (Parity.NONE, 2, 11),
}
BAUDRATES = (1200, 9600, 19200, 38400, 115200)


@pytest.mark.parametrize("baudrate", BAUDRATES)
@pytest.mark.parametrize("name", sorted(FORMATS))
def test_character_time_t15_and_t35(baudrate: int, name: str) -> None:
    parity, stopbits, bits = FORMATS[name]
    line = LineSettings(baudrate, 8, parity, stopbits)
    assert line.bits_per_character == bits
    assert line.char_time == pytest.approx(bits / baudrate, rel=1e-12)
    if baudrate > 19200:
        assert line.t1_5 == FIXED_T1_5 == 750e-6
        assert line.t3_5 == FIXED_T3_5 == 1750e-6
    else:
        assert line.t1_5 == pytest.approx(1.5 * bits / baudrate, rel=1e-12)
        assert line.t3_5 == pytest.approx(3.5 * bits / baudrate, rel=1e-12)


def test_exact_numbers_of_the_spec_default_and_9600() -> None:
    spec_default = LineSettings()
    assert (spec_default.baudrate, spec_default.parity, spec_default.stopbits) == (
        19200,
        Parity.EVEN,
        1,
    )
    assert spec_default.char_time == pytest.approx(572.916666e-6, rel=1e-6)
    assert spec_default.t3_5 == pytest.approx(2.005208333e-3, rel=1e-9)
    line = LineSettings(9600)
    assert line.t1_5 == pytest.approx(1.71875e-3, rel=1e-12)
    assert line.t3_5 == pytest.approx(4.0104166666e-3, rel=1e-9)
    assert LineSettings(1200).t3_5 == pytest.approx(32.083333e-3, rel=1e-6)


def test_wire_time_and_transaction_rate() -> None:
    line = LineSettings(19200)
    assert line.wire_time(256) == pytest.approx(256 * 11 / 19200)
    # A read of 10 registers: 8-byte request, 25-byte reply, two t3.5 silences.
    expected = (33 * 11 / 19200) + 2 * 3.5 * 11 / 19200
    assert line.transaction_time(8, 25) == pytest.approx(expected)
    assert line.transaction_rate(8, 25) == pytest.approx(1 / expected)
    fast = LineSettings(115200)
    assert fast.transaction_time(8, 25) == pytest.approx(33 * 11 / 115200 + 2 * 1750e-6)


@given(st.integers(1, 4_000_000), st.sampled_from("NEO"), st.sampled_from([1, 2]))
def test_the_fixed_timers_apply_exactly_above_19200(
    baudrate: int, parity: str, stopbits: int
) -> None:
    line = LineSettings(baudrate, parity=parity, stopbits=stopbits)
    if baudrate > 19200:
        assert (line.t1_5, line.t3_5) == (750e-6, 1750e-6)
    else:
        assert math.isclose(line.t3_5, 3.5 * line.char_time)
        assert math.isclose(line.t1_5, 1.5 * line.char_time)
    assert line.wire_time(10) == pytest.approx(10 * line.char_time)


def test_parity_is_normalised() -> None:
    assert LineSettings(parity="even").parity is Parity.EVEN
    assert LineSettings(parity="n").parity is Parity.NONE
    assert str(LineSettings(9600, parity="N", stopbits=2)) == "9600 8N2"


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"baudrate": 0}, "baudrate"),
        ({"baudrate": -9600}, "baudrate"),
        ({"baudrate": 9600.5}, "baudrate"),
        ({"bytesize": 9}, "bytesize"),
        ({"parity": "X"}, "parity"),
        ({"stopbits": 3}, "stopbits"),
    ],
)
def test_bad_settings_name_the_field(kwargs: dict[str, object], field: str) -> None:
    with pytest.raises(InvalidValue) as caught:
        LineSettings(**kwargs)  # type: ignore[arg-type]
    assert caught.value.field == field
    assert caught.value.value == kwargs[field]
    assert field in str(caught.value)
