"""Whatever a profile file holds, loading it gives a profile or one ConfigError line naming the
file and the key: never another exception, never a traceback."""

from __future__ import annotations

from typing import Any

from hypothesis import example, given, settings
from hypothesis import strategies as st

from aiortu.core.model import parse_profile
from aiortu.core.model._profile_dump import _value
from aiortu.errors import ConfigError

GOOD_POINT = {"name": "p", "address": 3, "type": "f32", "scale": 0.5, "access": "rw", "min": 0}
KEYS = [
    "name", "table", "address", "type", "size", "layout", "encoding", "scale", "offset",
    "scale_factor", "not_available", "unit", "access", "min", "max", "poll", "values", "bits",
    "value", "meta", "colour",
]  # fmt: skip
SCALARS = (
    st.integers(-70000, 70000)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=6)
    | st.booleans()
    | st.sampled_from(["u16", "f32", "string", "enum", "bitfield", "coils", "CDAB", "r", "rw"])
)
VALUES = st.recursive(
    SCALARS,
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner, max_size=3)
    ),
    max_leaves=6,
)


def _is_tables(value: object) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(i, dict) for i in value)


def toml(document: dict[str, Any]) -> str:
    """`document` as TOML: plain keys first, then tables and arrays of tables."""
    lines = [
        f"{key} = {_value(value)}"
        for key, value in document.items()
        if not isinstance(value, dict) and not _is_tables(value)
    ]
    for key, value in document.items():
        items = [value] if isinstance(value, dict) else value if _is_tables(value) else []
        header = f"[{key}]" if isinstance(value, dict) else f"[[{key}]]"
        for item in items:
            lines += [header, *(f"{_value(k)} = {_value(v)}" for k, v in item.items())]
    return "\n".join(lines) + "\n"


@settings(max_examples=400, deadline=None)
@given(
    changes=st.lists(st.tuples(st.sampled_from(KEYS), VALUES), max_size=4),
    device=st.dictionaries(
        st.sampled_from(["manufacturer", "model", "url", "x"]), VALUES, max_size=3
    ),
    defaults=st.dictionaries(
        st.sampled_from(["table", "layout", "base", "max_block", "max_gap", "poll"]),
        VALUES,
        max_size=3,
    ),
)
@example(changes=[("type", "string")], device={}, defaults={})
def test_any_file_loads_or_is_one_named_error(
    changes: list[tuple[str, Any]], device: dict[str, Any], defaults: dict[str, Any]
) -> None:
    point = dict(GOOD_POINT)
    for key, value in changes:
        point[key] = value
    document = {
        "device": {"manufacturer": "A", "model": "B"} | device,
        "defaults": defaults,
        "point": [point, {"name": "q", "address": 100}],
    }
    try:
        text = toml(document)
    except TypeError:
        return  # a value TOML cannot hold (none here, but the writer refuses rather than lies)
    try:
        parse_profile(text, "fuzz.toml")
    except ConfigError as error:
        message = str(error)
        assert message.startswith("fuzz.toml"), message
        assert "\n" not in message, message
