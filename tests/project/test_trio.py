"""Everything that does not touch pyserial runs under trio as well as under asyncio.

The suite runs in pytest-asyncio's auto mode, which takes every ``async def`` test for
asyncio; so these tests are synchronous and run their scenario with :func:`anyio.run`
on the backend of the ``anyio_backend`` fixture. Under trio the link has no event loop
with ``call_at`` (``link.loop`` is ``None``), so the master and the slave wait on anyio
events and cancel scopes, the virtual bus wakes on anyio's timers, and a push stream is
read through ``receive()``: the routes checked here.

The first part re-runs existing tests under trio (their own modules run them under
asyncio); the second runs scenarios written for both backends: the master and the slave
over a virtual pair, a raw pty (file descriptor streams) and TCP, retries, timeouts and
cancellation. The pytest fixtures under trio are checked in
``tests/testing/test_pytest_plugin.py``.
"""

from __future__ import annotations

import importlib
import itertools
import os
from collections.abc import Awaitable, Callable
from typing import Any

import anyio
import pytest
from anyio.abc import SocketAttribute, SocketStream

import aiortu
from aiortu.core.model import Table
from aiortu.core.serial import LineSettings
from aiortu.testing import VirtualBus, make_raw, virtual_pair
from aiortu.transport import FileDescriptorStream, open_serial
from tests.master.fakes import line, register_value, silent
from tests.transport.ptys import open_pty

pytestmark = pytest.mark.timeout(60)

BACKENDS = ("asyncio", "trio")

REUSED = {
    "tests.master.test_master_api": (
        "test_reads_return_the_values_trimmed_to_the_count",
        "test_writes_send_the_request_and_verify_the_echo",
        "test_the_other_function_codes",
        "test_the_unit_handle_and_typed_values",
        "test_broadcast_waits_the_turnaround_and_no_reply",
    ),
    "tests.gateway.test_forwarding": (
        "test_a_user_defined_code_goes_through_byte_for_byte",
        "test_ids_are_the_clients_own_and_pipelined_requests_all_answered",
    ),
    "tests.gateway.test_fairness": (
        "test_a_flooding_client_cannot_starve_a_quiet_one",
        "test_identical_reads_in_flight_at_once_are_one_transaction",
    ),
    "tests.gateway.test_lines": ("test_each_unit_goes_to_its_line_and_only_there",),
    "tests.gateway.test_cache": (
        "test_through_the_gateway_reads_hit_the_cache_until_a_write_or_the_age",
    ),
    "tests.gateway.test_unix_and_metrics": ("test_metrics_are_served_as_prometheus_text",),
    "tests.master.test_master_faults": (
        "test_no_reply_times_out_after_the_retries",
        "test_a_bad_crc_then_the_right_reply",
        "test_a_reply_from_another_unit_is_skipped",
        "test_an_exception_reply_raises_and_is_not_retried",
        "test_many_callers_share_one_line",
        "test_health_offline_after_failures_and_online_after_a_success",
        "test_requests_in_flight_fail_when_the_line_dies",
        "test_priority_goes_first",
        "test_cancelled_callers_never_desynchronise_the_line",
    ),
    "tests.master.test_tcp_master": (
        "test_every_master_method_against_the_modbus_tcp_server",
        "test_a_reply_with_another_transaction_id_is_dropped_and_counted",
        "test_the_master_reconnects_when_the_server_closes_the_connection",
    ),
    "tests.master.test_poller": (
        "test_the_requests_on_the_wire_are_the_merged_ranges_and_values_decode",
        "test_samples_reach_callbacks_and_the_async_iterator",
        "test_a_dead_unit_does_not_stall_the_cycle",
    ),
    "tests.slave.test_slave_line": (
        "test_each_unit_answers_from_its_own_store",
        "test_broadcast_write_is_executed_by_every_unit_and_not_answered",
        "test_listen_only_monitors_and_neither_executes_nor_answers",
        "test_custom_sync_and_async_handlers",
        "test_serve_ends_with_connection_lost_when_the_line_closes",
    ),
    "tests.testing.test_virtual_bus": (
        "test_pacing_at_9600_8e1",
        "test_paced_bytes_do_not_arrive_early",
        "test_trace_is_paced_and_non_overlapping",
        "test_closing_the_bus_wakes_receivers",
    ),
    "tests.testing.test_pty_bus": ("test_async_with_in_the_test_loop",),
    "tests.transport.test_fd": ("test_other_side_closed_is_end_of_stream",),
    "tests.transport.test_tcp": (
        "test_frames_travel_both_ways",
        "test_server_closing_is_end_of_stream",
    ),
}
"""Existing argument-less tests, by module, that run under trio here as they are, on the real
clock. The gateway's tests of times run under trio in their own modules, on trio's MockClock:
their waits are long and their times exact, which only a virtual clock keeps."""


def _reused(module: str, name: str) -> Callable[[], Awaitable[None]]:
    test = getattr(importlib.import_module(module), name, None)
    assert test is not None, f"{module}.{name} is gone: update REUSED in {__name__}"
    # A test on the virtual clock (tests/virtual_clock.py) keeps its scenario apart.
    return getattr(test, "scenario", test)  # type: ignore[no-any-return]


@pytest.fixture(params=BACKENDS)
def anyio_backend(request: pytest.FixtureRequest) -> str:
    """The backend a scenario runs on: both, in turn."""
    return str(request.param)


def run(backend: str, scenario: Callable[..., Awaitable[None]], *args: Any) -> None:
    anyio.run(scenario, *args, backend=backend)


@pytest.mark.parametrize(
    ("module", "name"),
    [(module, name) for module, names in REUSED.items() for name in names],
    ids=[name.removeprefix("test_") for names in REUSED.values() for name in names],
)
def test_existing_test_under_trio(module: str, name: str) -> None:
    run("trio", _reused(module, name))


# -- scenarios on both backends -------------------------------------------------------


def _store() -> aiortu.MemoryStore:
    return aiortu.MemoryStore(holding_registers={0: 100}, coils={0: 64})


async def _exercise(master: aiortu.Master, store: aiortu.MemoryStore) -> None:
    """Reads, writes, an exception, a broadcast and a timeout, on a master whose line
    has a slave serving unit 17 from *store*."""
    with anyio.fail_after(10):
        await master.write_registers(17, 0, [1, 2, 3])
        assert await master.read_holding_registers(17, 0, 3) == [1, 2, 3]
        await master.write_coil(17, 5, True)
        assert await master.read_coils(17, 4, 3) == [False, True, False]
        with pytest.raises(aiortu.ExceptionResponse):
            await master.read_holding_registers(17, 99, 5)
        await master.broadcast.write_register(10, 0xBEEF)
        assert await master.read_holding_registers(17, 10, 1) == [0xBEEF]
        with pytest.raises(aiortu.ResponseTimeout):
            await master.read_holding_registers(18, 0, 1, timeout=0.05)
    assert store.get(Table.HOLDING_REGISTERS, 0, 3) == [1, 2, 3]


def test_master_and_slave_on_a_virtual_pair(anyio_backend: str) -> None:
    async def scenario() -> None:
        near, far = virtual_pair()
        store = _store()
        async with (
            aiortu.Slave(far, {17: store}, frame_gap=0),
            aiortu.Master(near, frame_gap=0, retries=0) as master,
        ):
            await _exercise(master, store)
            assert master.engine.link.loop is None or anyio_backend == "asyncio"

    run(anyio_backend, scenario)


def test_master_and_slave_on_a_paced_virtual_bus(anyio_backend: str) -> None:
    settings = LineSettings(38400)

    async def scenario() -> None:
        async with VirtualBus(2, settings=settings) as bus:
            store = _store()
            async with (
                aiortu.Slave(bus[1], {17: store}, settings),
                aiortu.Master(bus[0], settings, retries=0) as master,
            ):
                await _exercise(master, store)
            trace = list(bus.trace)
        # The master and the slave each kept t3.5 of silence before they sent.
        gaps = [after.start - before.end for before, after in itertools.pairwise(trace)]
        assert gaps
        assert min(gaps) >= settings.t3_5 - 1e-6

    run(anyio_backend, scenario)


def test_master_and_slave_over_a_raw_pty(anyio_backend: str) -> None:
    async def scenario() -> None:
        device, port = os.openpty()
        make_raw(port)
        store = _store()
        settings = LineSettings(115200)
        async with (
            aiortu.Slave(FileDescriptorStream(device), {17: store}, settings),
            aiortu.Master(FileDescriptorStream(port), settings, retries=0) as master,
        ):
            await _exercise(master, store)

    run(anyio_backend, scenario)


def test_master_over_tcp_to_a_slave(anyio_backend: str) -> None:
    async def scenario() -> None:
        store = _store()

        async def serve(client: SocketStream) -> None:
            async with aiortu.Slave(client, {17: store}, frame_gap=0) as slave:
                await slave.wait_stopped()

        listener = await anyio.create_tcp_listener(local_host="127.0.0.1")
        async with listener, anyio.create_task_group() as tg:
            tg.start_soon(listener.serve, serve)
            port = listener.extra(SocketAttribute.local_port)
            # open_master: the URL, the transport and the reconnecting connection.
            url = f"rtu+tcp://127.0.0.1:{port}"
            async with aiortu.open_master(url, frame_gap=0, retries=0) as master:
                await _exercise(master, store)
            tg.cancel_scope.cancel()

    run(anyio_backend, scenario)


def test_master_over_modbus_tcp_to_a_slave(anyio_backend: str) -> None:
    async def scenario() -> None:
        with anyio.fail_after(10):
            await _modbus_tcp_scenario()

    async def _modbus_tcp_scenario() -> None:
        store = _store()
        async with (
            aiortu.serve("tcp://127.0.0.1:0", {17: store}) as server,
            aiortu.open_master(f"tcp://127.0.0.1:{server.port}", retries=0) as master,
        ):
            await master.write_registers(17, 0, [1, 2, 3])
            assert await master.read_holding_registers(17, 0, 3) == [1, 2, 3]
            await master.write_coil(17, 5, True)
            assert await master.read_coils(17, 4, 3) == [False, True, False]
            with pytest.raises(aiortu.ExceptionResponse) as refused:
                await master.read_holding_registers(17, 99, 5)
            assert refused.value.code == 2
            # Unit 0 reaches the one unit served; its reply never answers the next read.
            await master.broadcast.write_register(10, 0xBEEF)
            assert await master.read_holding_registers(17, 10, 1) == [0xBEEF]
            # A unit the server does not serve: exception 0B (no target), not a timeout.
            with pytest.raises(aiortu.ExceptionResponse) as refused:
                await master.read_holding_registers(18, 0, 1)
            assert refused.value.code == 0x0B
        assert store.get(Table.HOLDING_REGISTERS, 0, 3) == [1, 2, 3]

    run(anyio_backend, scenario)


def test_the_serial_port_says_it_runs_on_asyncio_only_under_trio() -> None:
    async def scenario() -> None:
        with open_pty() as pty:
            with pytest.raises(RuntimeError, match="asyncio only"):
                await open_serial(pty.path)
            with pytest.raises(RuntimeError, match="asyncio only"):
                async with aiortu.open_master(pty.path):
                    pass

    run("trio", scenario)


def test_a_retry_after_a_silent_attempt_gets_the_reply(anyio_backend: str) -> None:
    async def scenario() -> None:
        # The first attempt gets no reply; a later one does, within a timeout no load
        # reaches (spare retries for the unlikely case that it does).
        async with line(script={0: silent}, timeout=0.5, retries=3) as (master, slave, _):
            assert await master.read_holding_registers(3, 7, 2) == [
                register_value(3, 7),
                register_value(3, 8),
            ]
            stats = master.unit_stats(3)
            assert stats.timeouts >= 1
            assert (stats.retries, stats.successes) == (stats.timeouts, 1)
            assert len(slave.seen) == stats.timeouts + 1

    run(anyio_backend, scenario)
