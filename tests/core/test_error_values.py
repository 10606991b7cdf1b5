"""How an error message shows the value it refuses."""

from __future__ import annotations

import enum

from aiortu.core.codes import FunctionCode
from aiortu.core.errors import InvalidValue


class _Mode(enum.Enum):
    FAST = "fast"


def test_an_enum_member_is_shown_by_its_name_not_its_repr() -> None:
    # An IntEnum is an int too: its repr would show `<FunctionCode.READ_COILS: 1>`.
    refused = InvalidValue("function_code", FunctionCode.READ_COILS, range(2, 5))
    assert str(refused) == (
        "function_code = FunctionCode.READ_COILS is outside the allowed range 2..4"
    )
    assert str(InvalidValue("mode", _Mode.FAST, "a mode")) == "mode must be a mode, not _Mode.FAST"
