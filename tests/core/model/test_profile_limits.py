"""Profile checks at their edges: numeric-only keys, equal limits, and a bool's 0 and 1."""

from __future__ import annotations

import pytest

from aiortu.core.model import check_value, parse_profile
from aiortu.errors import ConfigError

HEAD = '[device]\nmanufacturer = "ACME"\nmodel = "M1"\n'


@pytest.mark.parametrize("key", ["scale = 2", "offset = 1", "min = 0", "max = 1"])
def test_numeric_keys_are_refused_on_a_string_point(key: str) -> None:
    text = HEAD + f'[[point]]\nname = "a"\naddress = 0\ntype = "string"\nsize = 2\n{key}\n'
    with pytest.raises(ConfigError) as caught:
        parse_profile(text, "meter.toml")
    name = key.partition(" = ")[0]
    assert str(caught.value).endswith(f"point a.{name}: is only for numeric points, not string")


def test_a_minimum_equal_to_the_maximum_is_allowed() -> None:
    profile = parse_profile(HEAD + '[[point]]\nname = "a"\naddress = 0\nmin = 3\nmax = 3\n', "m")
    (point,) = profile.points
    assert (point.minimum, point.maximum) == (3, 3)


def test_a_bool_point_takes_0_and_1_as_well_as_false_and_true() -> None:
    text = HEAD + '[[point]]\nname = "on"\ntable = "coils"\naddress = 0\ntype = "bool"\n'
    (point,) = parse_profile(text, "m").points
    assert [check_value(point, value) for value in (0, 1, False, True)] == [
        False,
        True,
        False,
        True,
    ]
