"""Run a :class:`~tests.torture.scenarios.MasterScenario`: callers storm one master whose
line carries good, slow, late, dead and confused devices, and every invariant is checked.

The line: port 0 is the master's, port 1 a :class:`aiortu.Slave` serving the good units
from :class:`aiortu.MemoryStore`\\ s (its fast paths), then one slave per odd device
(a hook turns each answer into a :class:`aiortu.Reply` that is late, silent or from
another unit), then the spare ports the master's port is "plugged back" as after it was
pulled (on a VirtualBus; a PtyBus keeps its ports).

How long a call may take. A call ends (with a result, a typed aiortu error or its
cancellation) once every call queued ahead of it has ended and its own attempts are
over; in the worst case it waits for every other call. So its bound is the sum, over
all calls, of one call's worst case: (retries + 1) x (its timeout + the wire time of a
request and its reply + the t3.5 silences + the late-reply guard) + the broadcast
turnaround, plus for each unplug the time the port stays out and the reconnect delay.
The guard is counted per attempt: every attempt may wait for the silence a failed attempt
before it leaves, its own call's or the call's ahead of it, and on a noisy line bytes
may start that silence again once, so there it counts twice.
That bound is checked per call and, with a margin for a loaded machine, as a hard
limit on the whole scenario: it catches hangs, not slowness.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import AsyncIterator, Callable
from typing import Any

import anyio
import anyio.abc

import aiortu
import aiortu.transport
from aiortu.testing import PtyBus, VirtualBus, VirtualEndpoint

from .checks import Ledger, Leftovers, Report, check_t3_5, logged_errors
from .scenarios import (
    CONSTANT,
    CONSTANTS,
    MAX_CALLERS,
    OWN,
    Call,
    Caller,
    Device,
    MasterScenario,
    constant,
    encode,
)

__all__ = ("run_master_scenario", "scenario_bound")

RECONNECT_DELAY = (0.005, 0.02)
HARD_LIMIT_SLACK = 30.0
"""Seconds on top of the bound before a scenario counts as hung (a loaded machine)."""
SCHEDULING_SLACK = 0.05
"""Per call: what a loaded 2-core machine may add to a call's own worst case (seed 7323 of
the soak overran a 10 ms slack by 1 ms while benchmarks ran beside it)."""


def _store(unit: int) -> aiortu.MemoryStore:
    return aiortu.MemoryStore(
        holding_registers={
            OWN: [0] * MAX_CALLERS,
            CONSTANT: [constant(unit, offset) for offset in range(CONSTANTS)],
        }
    )


def _odd_hook(device: Device) -> Callable[[Any, aiortu.RequestContext, Any], Any]:
    """The after-request hook that makes a unit slow, late, dead or confused."""

    def hook(request: Any, context: aiortu.RequestContext, result: Any) -> Any:
        if context.broadcast or not isinstance(result, aiortu.Response):
            return None
        if device.behaviour == "dead":
            return aiortu.Reply(None)
        if device.behaviour == "wrong_unit":
            return aiortu.Reply(result, unit=device.answer_as)
        return aiortu.Reply(result, delay=device.delay)

    return hook


def _call_bound(scenario: MasterScenario, call: Call) -> float:
    settings = scenario.settings
    wire = settings.transaction_time(11, 11) if scenario.baudrate else 0.0
    timeout = call.timeout or scenario.timeout
    turnaround = _turnaround(scenario) if call.kind == "broadcast" else 0.0
    attempts = scenario.retries + 1
    guard = scenario.late_reply_guard * (2 if scenario.faults is not None else 1)
    # SCHEDULING_SLACK: a loaded machine wakes a task late; a lost wake-up still costs seconds.
    return attempts * (timeout + wire + guard) + turnaround + SCHEDULING_SLACK


def _turnaround(scenario: MasterScenario) -> float:
    return 0.01 + (scenario.settings.wire_time(11) if scenario.baudrate else 0.0)


def scenario_bound(scenario: MasterScenario) -> float:
    """The longest any call of *scenario* may take (see the module docstring)."""
    calls = sum(
        _call_bound(scenario, call) + call.pause
        for caller in scenario.callers
        for call in caller.calls
    )
    return calls + len(scenario.unplugs) * (scenario.absent + 2 * RECONNECT_DELAY[1])


async def _perform(master: aiortu.Master, caller: int, sequence: int, call: Call) -> Any:
    """Make *call*; return what a read read (None for writes)."""
    unit, address, timeout, priority = call.unit, call.address, call.timeout, call.priority
    if call.kind in ("read_own", "read_constant"):
        return await master.read_holding_registers(
            unit, address, call.count, timeout=timeout, priority=priority
        )
    value = encode(caller, sequence)
    if call.kind == "write":
        await master.write_registers(unit, address, [value], timeout=timeout, priority=priority)
    elif call.kind == "write_one":
        await master.write_register(unit, address, value, timeout=timeout, priority=priority)
    else:
        await master.broadcast.write_register(address, value, priority=priority)
    return None


async def _cancelled_at(scope: anyio.CancelScope, delay: float) -> None:
    await anyio.sleep(delay)
    scope.cancel()


async def _typed(master: aiortu.Master, caller: int, sequence: int, call: Call) -> tuple[str, Any]:
    """Make *call*: ("ok", what a read read) or (the aiortu error's name, None)."""
    try:
        return "ok", await _perform(master, caller, sequence, call)
    except aiortu.ModbusError as error:
        return type(error).__name__, None


async def _outcome(
    master: aiortu.Master, caller: int, sequence: int, call: Call
) -> tuple[str, Any]:
    """Make *call* under its cancellation; the outcome's name and what a read read."""
    if call.cancel == "move_on":
        with anyio.move_on_after(call.cancel_after) as scope:
            return await _typed(master, caller, sequence, call)
        return "cancelled", None
    if call.cancel == "scope":
        scope = anyio.CancelScope()
        result: tuple[str, Any] = ("cancelled", None)
        async with anyio.create_task_group() as helpers:
            helpers.start_soon(_cancelled_at, scope, call.cancel_after)
            with scope:
                result = await _typed(master, caller, sequence, call)
            helpers.cancel_scope.cancel()
        return result
    return await _typed(master, caller, sequence, call)


async def _run_caller(
    scenario: MasterScenario, master: aiortu.Master, caller: Caller, ledger: Ledger, report: Report
) -> None:
    bound = scenario_bound(scenario)
    for number, call in enumerate(caller.calls):
        sequence = number + 1
        if call.pause:
            await anyio.sleep(call.pause)
        if call.kind in ("write", "write_one", "broadcast"):
            ledger.begin(caller.index, sequence)
        started = anyio.current_time()
        try:
            outcome, read = await _outcome(master, caller.index, sequence, call)
        except Exception as error:  # anything but a typed aiortu error is a bug
            report.violation(f"caller {caller.index} call {number} {call}: {error!r} escaped")
            continue
        report.operations += 1
        report.outcomes[outcome] += 1
        elapsed = anyio.current_time() - started
        if elapsed > bound:
            report.violation(
                f"caller {caller.index} call {number} took {elapsed:.3f} s > {bound:.3f} s"
            )
        if read is not None:
            wrong = ledger.check_read(call.unit, call.address, read)
            if wrong is not None:
                report.violation(f"caller {caller.index} call {number} {call}: {wrong}")


class _Plug:
    """The master's port on a VirtualBus: pulled out (its endpoint closed) and plugged
    back in (the next spare endpoint) once it has been out *absent* seconds."""

    def __init__(self, endpoints: list[VirtualEndpoint], absent: float) -> None:
        self.current = endpoints[0]
        self.spares = endpoints[1:]
        self.absent = absent
        self.back_at = -math.inf
        self.plugged_in = anyio.Event()
        """Set while the master's port is in: cleared by a pull, set by the master's reopen."""
        self.plugged_in.set()

    async def open(self) -> anyio.abc.ByteStream:
        if anyio.current_time() < self.back_at or not self.spares:
            raise OSError("the port is unplugged")
        self.current = self.spares.pop(0)
        self.plugged_in.set()
        # A port plugged in hears nothing of what went before (its buffer was not there).
        while self.current._take():
            pass
        return self.current

    async def pull_at(self, moments: tuple[float, ...]) -> None:
        start = anyio.current_time()
        for moment in moments:
            await anyio.sleep_until(start + moment)
            self.back_at = anyio.current_time() + self.absent
            if self.plugged_in.is_set():
                self.plugged_in = anyio.Event()
            await self.current.aclose()


async def _storm(
    scenario: MasterScenario, master: aiortu.Master, report: Report, plug: _Plug | None = None
) -> None:
    ledger = Ledger()
    async with anyio.create_task_group() as callers:
        for caller in scenario.callers:
            callers.start_soon(_run_caller, scenario, master, caller, ledger, report)
        if plug is not None and scenario.unplugs:
            callers.start_soon(plug.pull_at, scenario.unplugs)
    # After the storm the line is free: a fresh read succeeds (on a noisy line, one of
    # five: noise may garble or drop the request or the reply of a few). A pull may end
    # the storm: until the master has noticed it, it is still "connected", and a request
    # made then fails with the lost line as documented, so wait for its reopen first.
    with anyio.fail_after(5 + 4 * RECONNECT_DELAY[1] + scenario.absent):
        if plug is not None:
            await plug.plugged_in.wait()
        await master.connection.wait_connected()
    # A timeout far above any reply time: only a line that is not free misses it, not a
    # machine too loaded to run the slave in time.
    attempts, timeout = (5, 1.0) if scenario.faults is not None else (1, 5.0)
    for attempt in range(attempts):
        try:
            values = await master.read_holding_registers(1, CONSTANT, 3, timeout=timeout)
        except aiortu.ModbusError as error:
            noise = isinstance(error, aiortu.FrameError | aiortu.ResponseTimeout)
            if attempt == attempts - 1 or not noise:
                report.violation(f"the fresh read after the storm failed: {error!r}")
                return
            continue
        expected = [constant(1, offset) for offset in range(3)]
        if values != expected:
            report.violation(f"the fresh read gave {values}, not {expected}")
        return


@contextlib.asynccontextmanager
async def _slaves(
    scenario: MasterScenario, streams: list[anyio.abc.ByteStream]
) -> AsyncIterator[None]:
    """Serve the good units on *streams[0]* and one odd device on each of the next."""
    settings, gap = scenario.settings, None if scenario.baudrate else 0.0
    good = [d.unit for d in scenario.devices if d.behaviour == "good"]
    odd = [d for d in scenario.devices if d.behaviour != "good"]
    async with contextlib.AsyncExitStack() as stack:
        units = {unit: _store(unit) for unit in good}
        await stack.enter_async_context(aiortu.Slave(streams[0], units, settings, frame_gap=gap))
        for device, stream in zip(odd, streams[1:], strict=False):
            slave = aiortu.Slave(
                stream, {device.unit: _store(device.unit)}, settings, frame_gap=gap
            )
            slave.after_request(_odd_hook(device))
            await stack.enter_async_context(slave)
        yield


def _master(scenario: MasterScenario, stream: anyio.abc.ByteStream, opener: Any) -> aiortu.Master:
    return aiortu.Master(
        stream,
        scenario.settings,
        timeout=scenario.timeout,
        retries=scenario.retries,
        frame_gap=None if scenario.baudrate else 0.0,
        late_reply_guard=scenario.late_reply_guard,
        turnaround_delay=_turnaround(scenario),
        opener=opener,
        reconnect_delay=RECONNECT_DELAY,
    )


def _slave_count(scenario: MasterScenario) -> int:
    return 1 + sum(1 for device in scenario.devices if device.behaviour != "good")


async def _on_virtual_bus(scenario: MasterScenario, report: Report) -> None:
    slaves = _slave_count(scenario)
    bus = VirtualBus(
        1 + slaves + len(scenario.unplugs),
        settings=scenario.settings if scenario.baudrate else None,
        faults=scenario.faults,
        trace_size=20 * (scenario.operations + 10) * (scenario.retries + 1),
    )
    ports = list(bus.endpoints)
    plug = _Plug([ports[0], *ports[1 + slaves :]], scenario.absent)
    async with bus, _slaves(scenario, list(ports[1 : 1 + slaves])):
        async with _master(scenario, ports[0], plug.open) as master:
            await _storm(scenario, master, report, plug)
        report.outcomes["bus_collisions"] += bus.collisions
        if scenario.baudrate and scenario.faults is None:
            broken = check_t3_5(bus.trace, scenario.settings.t3_5)
            if broken:
                report.violation(f"t3.5: {broken}")


async def _on_pty_bus(scenario: MasterScenario, report: Report) -> None:
    slaves = _slave_count(scenario)
    settings = scenario.settings
    async with PtyBus(
        1 + slaves,
        settings=settings if scenario.baudrate else None,
        trace_size=20 * (scenario.operations + 10) * (scenario.retries + 1),
    ) as bus:
        async with contextlib.AsyncExitStack() as stack:
            streams = []
            for path in bus.paths[1:]:
                streams.append(await aiortu.transport.open_stream(path, settings))
            await stack.enter_async_context(_slaves(scenario, streams))
            master = await stack.enter_async_context(
                aiortu.open_master(
                    bus.paths[0],
                    baudrate=settings.baudrate,
                    parity="N",
                    timeout=scenario.timeout,
                    retries=scenario.retries,
                    frame_gap=None if scenario.baudrate else 0.0,
                    late_reply_guard=scenario.late_reply_guard,
                    turnaround_delay=_turnaround(scenario),
                )
            )
            await _storm(scenario, master, report)
        if scenario.baudrate:
            broken = check_t3_5(bus.trace, settings.t3_5)
            if broken:
                report.violation(f"t3.5: {broken}")


async def run_master_scenario(scenario: MasterScenario) -> Report:
    """Run *scenario* and return its report (the violations found, if any)."""
    report = Report(scenario.seed, "master", scenario.describe())
    leftovers = Leftovers()
    limit = scenario_bound(scenario) + HARD_LIMIT_SLACK
    run = _on_virtual_bus if scenario.line == "virtual" else _on_pty_bus
    with logged_errors() as errors:
        try:
            with anyio.fail_after(limit):
                await run(scenario, report)
        except TimeoutError:
            report.violation(f"the scenario did not end within {limit:.1f} s")
        except BaseException as error:  # whatever escapes is a finding
            if isinstance(error, anyio.get_cancelled_exc_class()):
                raise
            report.violation(f"escaped the master: {error!r} {_causes(error)}")
    for record in errors:
        report.violation(f"logged: {record.getMessage()} {record.exc_info!r}")
    for left in leftovers.new():
        report.violation(f"left behind: {left}")
    return report


def _causes(error: BaseException) -> str:
    if isinstance(error, BaseExceptionGroup):
        return "; ".join(f"{e!r} {_causes(e)}" for e in error.exceptions)
    return ""
