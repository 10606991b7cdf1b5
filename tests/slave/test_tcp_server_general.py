"""The Modbus TCP server's tests again, its connections on anyio's streams (the general path)
rather than asyncio's transports, which test_tcp_server.py runs them on."""

from __future__ import annotations

import pytest

from aiortu.transport import _push_server as push_server_module
from tests.slave.test_tcp_server import (
    test_a_malformed_header_closes_only_its_connection,
    test_an_idle_connection_is_closed,
    test_an_over_long_length_field_closes_the_connection,
    test_connections_over_the_limit_are_closed,
    test_every_function_code_answers_as_on_a_serial_line,
    test_hooks_routes_and_replies_over_tcp,
    test_many_connections_at_once,
    test_random_requests_answered_as_on_a_serial_line,
    test_replies_carry_the_transaction_and_unit_id,
    test_requests_of_all_connections_run_one_at_a_time,
    test_requests_split_anywhere_and_pipelined,
    test_several_units_broadcast_on_0_and_refuse_unknown_units,
    test_trace_sees_each_request_and_reply_adu,
    test_unit_aliases_and_silence_for_unknown_units,
)

pytestmark = pytest.mark.timeout(30)

__all__ = (  # run again here, on the general path
    "test_a_malformed_header_closes_only_its_connection",
    "test_an_idle_connection_is_closed",
    "test_an_over_long_length_field_closes_the_connection",
    "test_connections_over_the_limit_are_closed",
    "test_every_function_code_answers_as_on_a_serial_line",
    "test_hooks_routes_and_replies_over_tcp",
    "test_many_connections_at_once",
    "test_random_requests_answered_as_on_a_serial_line",
    "test_replies_carry_the_transaction_and_unit_id",
    "test_requests_of_all_connections_run_one_at_a_time",
    "test_requests_split_anywhere_and_pipelined",
    "test_several_units_broadcast_on_0_and_refuse_unknown_units",
    "test_trace_sees_each_request_and_reply_adu",
    "test_unit_aliases_and_silence_for_unknown_units",
)


@pytest.fixture(autouse=True)
def general_path(monkeypatch: pytest.MonkeyPatch) -> None:
    """Connections on anyio's streams, on asyncio too."""
    monkeypatch.setattr(push_server_module, "loop_pushes", lambda: False)
