"""A misbehaving device against the master, and the check of what the caller gets.

A scripted device (:class:`tests.master.fakes.FakeSlave`) on a paced virtual line
answers the next request the way a fault says (:data:`FAULTS`): from another unit, with
another function code, truncated, split, late, twice... The caller must get the right
answer or a typed :class:`aiortu.ModbusError`, never wrong values, another exception or
a hang; and the read that follows, on a clean line, must be right.

Shared by the fault suite and ``benchmarks/soak_faults.py``.
"""

from __future__ import annotations

import contextlib
import random
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass, field

import anyio

import aiortu
from aiortu.core.pdu import Request
from aiortu.core.rtu import encode_frame
from aiortu.core.serial import LineSettings
from aiortu.master import Master
from aiortu.testing import VirtualBus
from tests.master.fakes import FakeSlave, coil_value, register_value, standard_reply, until_idle

__all__ = ("FAULTS", "MasterRig", "master_rig")

LINE = LineSettings(38400)
"""The paced line: fast enough for many transactions, slow enough for wire times to matter."""
TIMEOUT = 0.05
GUARD = 0.04

FAULTS = (
    "wrong unit",
    "wrong code",
    "exception for another code",
    "truncated",
    "short pdu",
    "long pdu",
    "over-long",
    "duplicated",
    "split",
    "late",
    "garbage before",
    "silent",
)
"""How the device may answer a request instead of the right way."""

Step = Callable[[FakeSlave, int, Request], Awaitable[None]]


def misbehaviour(fault: str, rng: random.Random) -> Step:
    """A step of the fake device that answers a request the way *fault* says."""

    async def step(device: FakeSlave, unit: int, request: Request) -> None:
        pdu = standard_reply(unit, request)
        frame = encode_frame(unit, pdu)
        if fault == "wrong unit":
            await device.reply(unit % 247 + 1, pdu)
        elif fault == "wrong code":
            await device.reply(unit, bytes((pdu[0] ^ 0x07,)) + pdu[1:])
        elif fault == "exception for another code":
            await device.reply(unit, bytes(((pdu[0] ^ 0x07) | 0x80, 0x02)))
        elif fault == "truncated":
            await device.send_raw(frame[: rng.randrange(1, len(frame))])
        elif fault == "short pdu":
            await device.reply(unit, pdu[:-1])
        elif fault == "long pdu":
            await device.reply(unit, pdu + rng.randbytes(rng.randrange(1, 5)))
        elif fault == "over-long":
            await device.send_raw(frame + rng.randbytes(rng.randrange(1, 8)))
        elif fault == "duplicated":
            await device.send_raw(frame + frame)
        elif fault == "split":
            cut = rng.randrange(1, len(frame))
            await device.send_raw(frame[:cut])
            await anyio.sleep(rng.uniform(0, 0.004))
            await device.send_raw(frame[cut:])
        elif fault == "late":
            # Within the late-reply guard: the master must drop it, or take it for a
            # retry of the same request.
            await anyio.sleep(TIMEOUT + rng.uniform(0.0, 0.6) * GUARD)
            await device.send_raw(frame)
        elif fault == "garbage before":
            await device.send_raw(rng.randbytes(rng.randrange(1, 12)) + frame)
        elif fault != "silent":
            raise AssertionError(f"no such fault: {fault}")

    return step


@dataclass
class MasterRig:
    """A master and a scripted device on a paced line; :meth:`operation` runs one faulted
    call and one clean call and says what broke the rules."""

    master: Master
    device: FakeSlave
    rng: random.Random
    fault: str | None = None
    """The fault for the device's next request (then back to answering right)."""
    outcomes: dict[str, int] = field(default_factory=dict)

    async def answer(self, device: FakeSlave, unit: int, request: Request) -> None:
        fault, self.fault = self.fault, None
        if fault is None:
            await device.reply(unit, standard_reply(unit, request))
        else:
            await misbehaviour(fault, self.rng)(device, unit, request)

    async def operation(self, fault: str) -> list[str]:
        """A call answered with *fault*, then a clean call; the rules they broke."""
        self.fault = fault
        problems = await self._call(fault, clean=False)
        self.fault = None
        return problems + await self._call(fault, clean=True)

    async def _call(self, fault: str, *, clean: bool) -> list[str]:
        rng = self.rng
        unit, address, count = rng.randrange(1, 6), rng.randrange(0, 1000), rng.randrange(1, 9)
        kind = rng.choice(("holding", "input", "coils", "write"))
        call, expected = _call(self.master, kind, unit, address, count)
        where = f"{fault}, {'the call after' if clean else 'the faulted call'}: {kind} {unit}"
        try:
            with anyio.fail_after(5):
                got = await call
        except aiortu.ModbusError as error:
            outcome = type(error).__name__
            if clean:
                return [f"{where}: {outcome} on a clean line ({error})"]
        except TimeoutError:
            return [f"{where}: no answer to the caller within 5 s"]
        except Exception as error:  # the violation the suite looks for
            return [f"{where}: untyped {type(error).__name__}: {error}"]
        else:
            outcome = "right answer"
            if got != expected:
                return [f"{where}: {got!r} instead of {expected!r}"]
        if not clean:
            key = f"{fault}: {outcome}"
            self.outcomes[key] = self.outcomes.get(key, 0) + 1
        return []


def _call(
    master: Master, kind: str, unit: int, address: int, count: int
) -> tuple[Awaitable[object], object]:
    """The master call of *kind* and the result the fake data model gives."""
    if kind == "holding":
        values = [register_value(unit, address + i) for i in range(count)]
        return master.read_holding_registers(unit, address, count), values
    if kind == "input":
        values = [register_value(unit, address + i) ^ 0xFFFF for i in range(count)]
        return master.read_input_registers(unit, address, count), values
    if kind == "coils":
        bits = [coil_value(unit, address + i) for i in range(count)]
        return master.read_coils(unit, address, count), bits
    return master.write_register(unit, address, count), None


@contextlib.asynccontextmanager
async def master_rig(rng: random.Random, retries: int = 1) -> AsyncIterator[MasterRig]:
    """A master (*retries*) and a scripted device on a paced two-port virtual bus."""
    bus = VirtualBus(2, settings=LINE)
    device = FakeSlave(bus.endpoints[1])
    async with anyio.create_task_group() as tasks:
        async with Master(
            bus.endpoints[0], LINE, timeout=TIMEOUT, retries=retries, late_reply_guard=GUARD
        ) as master:
            rig = MasterRig(master, device, rng)
            device.default = rig.answer
            tasks.start_soon(device.run)
            await until_idle(master, device)
            yield rig
        tasks.cancel_scope.cancel()
