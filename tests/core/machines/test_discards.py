"""What bytes the receiver discarded stand for, as the master reports them."""

from __future__ import annotations

import pytest

from aiortu.core.errors import CRCError, FrameError
from aiortu.core.machines import frame_error_from_discard
from aiortu.core.rtu import crc16


@pytest.mark.parametrize("reason", ["crc", "noise"])
def test_four_bytes_or_more_are_a_crc_error(reason: str) -> None:
    error = frame_error_from_discard(bytes.fromhex("11 03 02 00"), reason)
    assert isinstance(error, CRCError)
    computed = crc16(bytes.fromhex("11 03"))
    assert str(error) == f"CRC mismatch: frame carries 0x0002, content gives 0x{computed:04X}"


@pytest.mark.parametrize(("data", "reason"), [("11 03 02", "crc"), ("11 03 02 00", "short")])
def test_fewer_bytes_or_another_reason_are_a_frame_error(data: str, reason: str) -> None:
    error = frame_error_from_discard(bytes.fromhex(data), reason)
    assert type(error) is FrameError
    assert error.reason == reason
    assert str(error) == f"{len(data.split())} bytes discarded ({reason}): {data.lower()}"
