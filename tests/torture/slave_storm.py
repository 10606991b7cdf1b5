"""Run a :class:`~tests.torture.scenarios.SlaveScenario`: a slave on a bus with other
masters that send garbage, requests to other units and to ours, broadcasts and other
slaves' replies, while a checking master reads and writes; the slave's serve task is
cancelled mid-request and a new slave takes over the same stores on a spare port.

Checked: nothing but the cancellation ends a serve task (no SlaveMachineError, no
other exception, no logged error); the checking master only ever reads values that were
written; after the storm, on a quiet line, a read and a write of each unit succeed and
the slave's machine is back in IDLE; no task or timer is left behind.
"""

from __future__ import annotations

import contextlib
import random
from collections.abc import AsyncIterator, Awaitable, Callable, Sequence
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Any

import anyio
import anyio.abc

import aiortu
import aiortu.transport
from aiortu.core.machines import SlaveState
from aiortu.core.pdu import (
    ReadHoldingRegistersRequest,
    ReadHoldingRegistersResponse,
    WriteSingleRegisterRequest,
)
from aiortu.core.rtu import encode_frame
from aiortu.testing import PtyBus, TraceEntry, VirtualBus

from .checks import Ledger, Leftovers, Report, logged_errors
from .scenarios import (
    CONSTANT,
    CONSTANTS,
    LOAD_MARGIN,
    MAX_CALLERS,
    OWN,
    SlaveScenario,
    constant,
    encode,
)

__all__ = ("run_slave_scenario",)

SCRATCH = 1200
"""Registers the other masters' broadcasts write (nobody checks them)."""
HARD_LIMIT = 60.0


def _store(unit: int) -> aiortu.MemoryStore:
    return aiortu.MemoryStore(
        holding_registers={
            OWN: [0] * MAX_CALLERS,
            CONSTANT: [constant(unit, offset) for offset in range(CONSTANTS)],
            SCRATCH: [0] * 10,
        }
    )


def _rogue_frame(generator: random.Random, units: tuple[int, ...]) -> bytes:
    """One transmission of another master (or of another slave) on the line."""
    kind = generator.choice(("garbage", "other_unit", "our_unit", "broadcast", "reply"))
    others = [unit for unit in range(1, 248) if unit not in units]
    if kind == "garbage":
        return generator.randbytes(generator.choice((1, 2, 3, 5, 9, 13, 30)))
    if kind == "other_unit":
        pdu = ReadHoldingRegistersRequest(generator.randrange(0, 1000), 3).encode()
        return encode_frame(generator.choice(others), pdu)
    if kind == "our_unit":
        address = CONSTANT + generator.randrange(0, CONSTANTS - 5)
        # Never 5 registers, the checking master's count: RTU replies carry no
        # transaction id, so a reply to another master's read of the same shape would
        # pass its checks (one master per bus is the spec's rule).
        pdu = ReadHoldingRegistersRequest(address, generator.randint(1, 4)).encode()
        return encode_frame(generator.choice(units), pdu)
    if kind == "broadcast":
        pdu = WriteSingleRegisterRequest(SCRATCH + generator.randrange(10), 7).encode()
        return encode_frame(0, pdu)
    values = tuple(generator.randrange(65536) for _ in range(generator.randint(1, 5)))
    return encode_frame(generator.choice(others), ReadHoldingRegistersResponse(values).encode())


def _rogue_frames(scenario: SlaveScenario) -> list[list[bytes]]:
    """What each other master sends, drawn from the seed."""
    generators = [random.Random(scenario.seed * 1000 + index) for index in range(scenario.rogues)]
    return [
        [_rogue_frame(generator, scenario.units) for _ in range(scenario.frames)]
        for generator in generators
    ]


async def _rogue(port: anyio.abc.ByteStream, frames: list[bytes], seed: int) -> None:
    generator = random.Random(seed)
    for frame in frames:
        await anyio.sleep(generator.uniform(0, 0.01))
        await port.send(frame)


def _checking_timeout(scenario: SlaveScenario, frames: list[list[bytes]]) -> float:
    """A response timeout no reply of the slave can miss unless the slave is gone.

    The slave answers one request at a time: a request of the checking master may wait
    behind every request the other masters send our units or broadcast (each a hook's sleep and a
    transaction on the wire). A reply later than the timeout and the guard would be
    taken for the next read of the same shape (RTU's documented limit), so the timeout
    and the late-reply guard (the same, plus LOAD_MARGIN) cover them all. On a paced
    bus they also cover every byte the others send: the bus queues a transmission that
    collides behind the one on the wire, so a request may leave the wire that much later
    than its master reckons.
    """
    served = {0, *scenario.units}  # broadcasts too: the slave runs them, hook and all
    ours = sum(1 for sent in frames for frame in sent if len(frame) == 8 and frame[0] in served)

    wire = scenario.settings.transaction_time(8, 15) if scenario.baudrate else 0.0
    backlog = sum(len(frame) for sent in frames for frame in sent)
    char_time = scenario.settings.char_time if scenario.baudrate else 0.0
    return 0.05 + (ours + 2) * (scenario.slow_hook + wire + 0.002) + backlog * char_time


class _Generations:
    """The slaves that serve the stores one after the other, the current one last.

    At each restart time the current slave's serve task is cancelled: with
    *in_request*, from inside its before-request hook at the first request after that
    time (so always mid-request, the machine past IDLE); otherwise wherever it is.
    """

    def __init__(self, scenario: SlaveScenario, report: Report) -> None:
        self.scenario = scenario
        self.report = report
        self.stores = {unit: _store(unit) for unit in scenario.units}
        self.slaves: list[aiortu.Slave] = []
        self.scope = anyio.CancelScope()
        self.restart_at = float("inf")

    async def hook(self, request: Any, context: aiortu.RequestContext) -> None:
        if self.scenario.in_request and anyio.current_time() >= self.restart_at:
            self.scope.cancel()
        if self.scenario.slow_hook:
            await anyio.sleep(self.scenario.slow_hook)

    async def serve(self, ports: _Ports) -> None:
        scenario, start = self.scenario, anyio.current_time()
        gap = None if scenario.baudrate else 0.0
        for generation in range(len(scenario.restarts) + 1):
            port = await ports.open_slave_port(generation)
            slave = aiortu.Slave(port, self.stores, scenario.settings, frame_gap=gap)
            if scenario.slow_hook or scenario.in_request:
                slave.before_request(self.hook)
            self.slaves.append(slave)
            last = generation == len(scenario.restarts)
            self.restart_at = float("inf") if last else start + scenario.restarts[generation]
            self.scope = anyio.CancelScope()
            if not (last or scenario.in_request):
                self.scope.deadline = self.restart_at
            try:
                with self.scope:
                    await slave.serve()
            except Exception as error:  # anything escaping serve() is a finding
                self.report.violation(f"slave {generation}: {error!r} escaped serve()")
                return
            if not self.scope.cancelled_caught:
                self.report.violation(f"slave {generation}: serve() returned by itself")
                return
            # Where the cancellation found the slave (mid-request: past IDLE).
            self.report.outcomes[f"restart_in_{slave.machine.state.name}"] += 1


async def _check(
    master: aiortu.Master, scenario: SlaveScenario, ledger: Ledger, report: Report
) -> None:
    """The checking master's calls during the storm: reads and writes, values checked."""
    generator = random.Random(scenario.seed + 1)
    for sequence in range(1, scenario.checks + 1):
        unit = generator.choice(scenario.units)
        try:
            if generator.random() < 0.4:
                ledger.begin(0, sequence)
                await master.write_register(unit, OWN, encode(0, sequence))
                outcome = "ok"
            else:
                address = generator.choice((OWN, CONSTANT + generator.randrange(CONSTANTS - 5)))
                values = await master.read_holding_registers(unit, address, 5)
                wrong = ledger.check_read(unit, address, values)
                if wrong is not None:
                    report.violation(f"checking read {sequence}: {wrong}")
                outcome = "ok"
        except aiortu.ModbusError as error:
            outcome = type(error).__name__
        report.operations += 1
        report.outcomes[outcome] += 1
        await anyio.sleep(generator.uniform(0, 0.005))


async def _after_storm(
    master: aiortu.Master, generations: _Generations, ports: _Ports, report: Report
) -> None:
    """On a quiet line, every unit answers a write and reads it back; the machine idles."""
    # Quiet: the other masters' last bytes have left the wire (a paced bus queues them).
    trace = ports.trace()
    last = trace[-1].end if trace else 0.0
    await anyio.sleep_until(max(last, anyio.current_time()) + 0.05)
    for unit in generations.scenario.units:
        value = encode(0, 255)
        try:
            # Timeouts no reply misses on a quiet line, however loaded the machine.
            await master.write_register(unit, OWN, value, timeout=2.0)
            read = await master.read_holding_registers(unit, OWN, 1, timeout=2.0)
        except aiortu.ModbusError as error:
            report.violation(f"unit {unit} after the storm: {error!r}")
            continue
        if read != [value]:
            report.violation(f"unit {unit} after the storm read {read}, wrote {value}")
    state = generations.slaves[-1].machine.state
    if state is not SlaveState.IDLE:
        report.violation(f"the slave's machine is {state.name} after the storm")


@dataclass
class _Ports:
    """The line's ports: the checking master's, the other masters', and a function that
    opens the port of the slave of each generation (a device plugged in late hears
    nothing of what went before)."""

    checker: anyio.abc.ByteStream
    rogues: Sequence[anyio.abc.ByteStream]
    open_slave_port: Callable[[int], Awaitable[anyio.abc.ByteStream]]
    trace: Callable[[], Sequence[TraceEntry]]


@asynccontextmanager
async def _virtual_line(scenario: SlaveScenario) -> AsyncIterator[_Ports]:
    rogues, slaves = scenario.rogues, len(scenario.restarts) + 1
    bus = VirtualBus(1 + rogues + slaves, settings=scenario.settings if scenario.baudrate else None)
    ports = list(bus.endpoints)

    async def open_slave_port(generation: int) -> anyio.abc.ByteStream:
        port = ports[1 + rogues + generation]
        while port._take():
            pass
        return port

    async with bus:
        yield _Ports(ports[0], ports[1 : 1 + rogues], open_slave_port, lambda: bus.trace)


@asynccontextmanager
async def _pty_line(scenario: SlaveScenario) -> AsyncIterator[_Ports]:
    rogues, slaves, settings = scenario.rogues, len(scenario.restarts) + 1, scenario.settings
    bus = PtyBus(1 + rogues + slaves, settings=settings if scenario.baudrate else None)
    async with bus, contextlib.AsyncExitStack() as streams:

        async def open_port(index: int) -> anyio.abc.ByteStream:
            bus.discard_input(index)
            stream = await aiortu.transport.open_stream(bus.paths[index], settings)
            streams.push_async_callback(stream.aclose)
            return stream

        checker = await open_port(0)
        others = [await open_port(1 + index) for index in range(rogues)]
        yield _Ports(checker, others, lambda g: open_port(1 + rogues + g), lambda: bus.trace)


async def _slave_storm(scenario: SlaveScenario, report: Report) -> None:
    line = _virtual_line if scenario.line == "virtual" else _pty_line
    async with line(scenario) as ports:
        generations = _Generations(scenario, report)
        frames = _rogue_frames(scenario)
        timeout = _checking_timeout(scenario, frames)
        master = aiortu.Master(
            ports.checker,
            scenario.settings,
            timeout=timeout,
            retries=1,
            frame_gap=None if scenario.baudrate else 0.0,
            late_reply_guard=timeout + LOAD_MARGIN,
        )
        async with master, anyio.create_task_group() as serving:
            serving.start_soon(generations.serve, ports)
            async with anyio.create_task_group() as storm:
                for index, rogue in enumerate(ports.rogues):
                    storm.start_soon(_rogue, rogue, frames[index], scenario.seed + index)
                storm.start_soon(_check, master, scenario, Ledger(), report)
                if scenario.restarts:
                    await anyio.sleep(scenario.restarts[-1] + 0.01)
            # A restart still waiting for a request mid-request does not happen after
            # the storm: the checks below would lose their request to it.
            generations.restart_at = float("inf")
            report.outcomes["rogue_frames"] += scenario.rogues * scenario.frames
            report.operations += scenario.rogues * scenario.frames
            await _after_storm(master, generations, ports, report)
            serving.cancel_scope.cancel()


async def run_slave_scenario(scenario: SlaveScenario) -> Report:
    """Run *scenario* and return its report (the violations found, if any)."""
    report = Report(scenario.seed, "slave", scenario.describe())
    leftovers = Leftovers()
    with logged_errors() as errors:
        try:
            with anyio.fail_after(HARD_LIMIT):
                await _slave_storm(scenario, report)
        except TimeoutError:
            report.violation(f"the scenario did not end within {HARD_LIMIT:.0f} s")
        except Exception as error:  # whatever escapes is a finding
            report.violation(f"escaped: {error!r}")
    for record in errors:
        report.violation(f"logged: {record.getMessage()} {record.exc_info!r}")
    for left in leftovers.new():
        report.violation(f"left behind: {left}")
    return report
