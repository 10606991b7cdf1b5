"""A reference out of its form's range is refused with the range of that form."""

from __future__ import annotations

import pytest

from aiortu.core.errors import InvalidValue
from aiortu.core.model import parse_reference


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("40000", "reference must be 40001..49999, not '40000': numbers start at 1; "
                  "protocol address 0 is 40001"),
        ("400000", "reference must be 400001..465536, not '400000': numbers start at 1; "
                   "protocol address 0 is 400001"),
        ("0", "reference must be 00001..09999, not '0': numbers start at 1; "
              "protocol address 0 is 00001"),
        ("465537", "reference must be 400001..465536, not '465537': "
                   "a table has 65536 elements"),
    ],
)  # fmt: skip
def test_the_message_names_the_range_of_the_form_used(text: str, message: str) -> None:
    with pytest.raises(InvalidValue) as raised:
        parse_reference(text)
    assert str(raised.value) == message
