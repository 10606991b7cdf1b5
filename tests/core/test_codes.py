"""The function code ranges the spec leaves to users."""

from __future__ import annotations

from aiortu.core.codes import USER_DEFINED_FUNCTION_CODES, is_user_defined


def test_user_defined_codes_are_65_to_72_and_100_to_110() -> None:
    assert list(USER_DEFINED_FUNCTION_CODES) == [*range(65, 73), *range(100, 111)]
    assert [code for code in range(256) if is_user_defined(code)] == list(
        USER_DEFINED_FUNCTION_CODES
    )
