"""Which table a PDU reads or writes, as the monitor and the logs tell it."""

from __future__ import annotations

from typing import Any

import pytest

from aiortu.core.pdu import decode_request, decode_response, table_access

COILS, REGISTERS = "coils", "holding_registers"


@pytest.mark.parametrize(
    ("request_hex", "expected"),
    [
        ("01 0001 0002", {"table": COILS, "address": 1, "count": 2}),
        ("03 0001 0002", {"table": REGISTERS, "address": 1, "count": 2}),
        ("05 0003 FF00", {"table": COILS, "address": 3, "count": 1, "values": [True]}),
        ("06 0004 0009", {"table": REGISTERS, "address": 4, "count": 1, "values": [9]}),
        ("0F 0002 0003 01 05", {"table": COILS, "address": 2, "count": 3,
                                "values": [True, False, True]}),
        ("10 0001 0002 04 0001 0002", {"table": REGISTERS, "address": 1, "count": 2,
                                       "values": [1, 2]}),
        ("16 0007 FF00 0012", {"table": REGISTERS, "address": 7, "count": 1}),
        ("08 0000 1234", {}),
    ],
)  # fmt: skip
def test_requests(request_hex: str, expected: dict[str, Any]) -> None:
    assert table_access(decode_request(bytes.fromhex(request_hex)), None) == expected


@pytest.mark.parametrize(
    ("reply_hex", "request_hex", "expected"),
    [
        ("05 0003 FF00", None, {"table": COILS, "address": 3, "count": 1, "values": [True]}),
        ("06 0004 0009", None, {"table": REGISTERS, "address": 4, "count": 1, "values": [9]}),
        ("0F 0002 0003", None, {"table": COILS, "address": 2, "count": 3}),
        ("10 0001 0002", None, {"table": REGISTERS, "address": 1, "count": 2}),
        ("01 01 05", "01 0002 0003", {"table": COILS, "address": 2, "count": 3,
                                      "values": [True, False, True]}),
        ("01 01 05", None, {}),
        ("03 04 0001 0002", "03 0005 0002", {"table": REGISTERS, "address": 5, "count": 2,
                                             "values": [1, 2]}),
    ],
)  # fmt: skip
def test_replies(reply_hex: str, request_hex: str | None, expected: dict[str, Any]) -> None:
    request = decode_request(bytes.fromhex(request_hex)) if request_hex else None
    reply = decode_response(bytes.fromhex(reply_hex))
    assert table_access(reply, request) == expected
