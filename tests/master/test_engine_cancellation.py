"""Cancellation in the master's engine: callers cancelled while queued, in flight, and
the line task cancelled (the master closing) while it finishes what a caller left."""

from __future__ import annotations

from collections.abc import Callable

import anyio
import pytest

from aiortu.core.machines import MasterState
from aiortu.core.pdu import ReadHoldingRegistersRequest, Request
from aiortu.core.rtu import encode_frame
from aiortu.errors import ConnectionLost
from aiortu.master import Master
from aiortu.transport import open_serial
from tests.master.fakes import FakeSlave, answer, line, silent
from tests.transport.ptys import LINE, open_pty, read_master
from tests.virtual_clock import on_virtual_clock


async def _until(condition: Callable[[], bool]) -> None:
    with anyio.fail_after(2):
        while not condition():  # noqa: ASYNC110
            await anyio.sleep(0.001)


@on_virtual_clock
async def test_closing_while_the_line_task_finishes_a_cancelled_read_fails_the_queued_write() -> (
    None
):
    # The demo's shutdown: a read is on the wire, a write waits in the queue, the read's
    # caller is cancelled (the line task finishes its attempt), then the master closes
    # before the write's caller is cancelled. The line task must not hand the line to
    # the write: the machine still waits for the read's reply.
    ended: list[BaseException] = []
    async with anyio.create_task_group() as callers:
        # The machine's route; the fast path taken over is the pty test below.
        async with line(default=silent, timeout=5.0, retries=0, fast_path=False) as (
            master,
            _,
            bus,
        ):
            engine = master.engine
            read_scope = anyio.CancelScope()

            async def read() -> None:
                with read_scope:
                    await master.read_holding_registers(1, 0, 2)

            async def write() -> None:
                try:
                    await master.write_register(1, 0, 5)
                except Exception as error:  # what ended it is the point
                    ended.append(error)

            callers.start_soon(read)
            await _until(lambda: engine.machine.state is MasterState.WAITING_REPLY)
            callers.start_soon(write)
            await _until(lambda: engine.queued > 0)
            read_scope.cancel()
            await _until(lambda: engine.line_task.job is not None)
        with anyio.fail_after(2):
            while not ended:  # noqa: ASYNC110
                await anyio.sleep(0.001)
    assert len(ended) == 1
    assert isinstance(ended[0], ConnectionLost), ended
    assert engine.machine.state is MasterState.IDLE
    # Only the read went out: the write failed in the queue.
    sent = [entry.data for entry in bus.trace if entry.sender == 0]
    assert sent == [encode_frame(1, ReadHoldingRegistersRequest(0, 2).encode())]


async def _slow(slave: FakeSlave, unit: int, request: Request) -> None:
    await anyio.sleep(0.05)
    await answer(slave, unit, request)


@on_virtual_clock
async def test_a_caller_cancelled_while_queued_is_dropped_and_the_line_goes_on() -> None:
    async with line(default=_slow, timeout=1.0) as (master, slave, _):
        engine = master.engine
        async with anyio.create_task_group() as callers:
            first: list[list[int]] = []

            async def read_first() -> None:
                first.append(await master.read_holding_registers(1, 0, 2))

            queued = anyio.CancelScope()

            async def read_queued() -> None:
                with queued:
                    await master.read_holding_registers(1, 10, 2)

            callers.start_soon(read_first)
            await _until(lambda: engine.busy)
            callers.start_soon(read_queued)
            await _until(lambda: engine.queued > 0)
            queued.cancel()
        assert first == [[1000, 1001]]
        with anyio.fail_after(2):  # hangs if the cancelled caller was handed the line
            assert await master.read_holding_registers(1, 20, 1) == [1020]
        requests = [seen.request for seen in slave.seen]
        assert requests == [
            ReadHoldingRegistersRequest(0, 2),
            ReadHoldingRegistersRequest(20, 1),
        ]
        assert engine.transactions == 2
        assert not engine.busy


@pytest.mark.parametrize("cancel_after", [0.0, 0.02])
async def test_queued_callers_cancelled_in_any_order_leave_the_line_free(
    cancel_after: float,
) -> None:
    # Several queued callers, cancelled while the first is still waiting for its reply
    # or just as it ends: none of them is sent, and the line is free afterwards.
    async with line(default=_slow, timeout=1.0) as (master, slave, _):
        engine = master.engine
        scopes = [anyio.CancelScope() for _ in range(3)]

        async def read_queued(scope: anyio.CancelScope, address: int) -> None:
            with scope:
                await master.read_holding_registers(1, address, 1)

        async with anyio.create_task_group() as callers:
            callers.start_soon(master.read_holding_registers, 1, 0, 1)
            await _until(lambda: engine.busy)
            for index, scope in enumerate(scopes):
                callers.start_soon(read_queued, scope, 100 + index)
            await _until(lambda: engine.queued == len(scopes))
            await anyio.sleep(cancel_after)
            for scope in reversed(scopes):
                scope.cancel()
        with anyio.fail_after(2):
            assert await master.read_holding_registers(1, 7, 1) == [1007]
        assert [seen.request.address for seen in slave.seen] == [0, 7]  # type: ignore[attr-defined]
        assert not engine.busy
        assert engine.queued == 0


async def test_closing_while_the_line_task_runs_a_read_taken_over_fails_the_queued_write() -> None:
    # The same shutdown on a serial port, where the read ran as a usual exchange and the
    # machine took it over (another unit's frame came first).
    ended: list[BaseException] = []
    async with anyio.create_task_group() as callers:
        with open_pty() as pty:
            stream = await open_serial(pty.path, LINE)
            async with Master(stream, LINE, timeout=5.0, retries=0, frame_gap=0) as master:
                engine = master.engine
                await anyio.sleep(0.05)  # past the receiver's first silence

                async def read() -> None:
                    with pytest.raises(ConnectionLost):
                        await master.read_holding_registers(1, 0, 2)

                callers.start_soon(read)
                await read_master(pty, 8)
                assert engine.fast.on_wire  # the fast path's exchange waits

                async def write() -> None:
                    try:
                        await master.write_register(1, 0, 5)
                    except Exception as error:  # what ended it is the point
                        ended.append(error)

                callers.start_soon(write)
                await _until(lambda: engine.queued > 0)
                pty.write(encode_frame(2, bytes.fromhex("030400090009")))
                await _until(lambda: engine.line_task.job is not None)
            with anyio.fail_after(2):
                while not ended:  # noqa: ASYNC110
                    await anyio.sleep(0.001)
    assert isinstance(ended[0], ConnectionLost), ended
    assert engine.machine.state is MasterState.IDLE
