"""Seeded scenarios for the concurrency torture suite: everything a run does, drawn up front.

A scenario is a plain record drawn from ``random.Random(seed)``: the line (a
:class:`~aiortu.testing.VirtualBus` or a :class:`~aiortu.testing.PtyBus`, paced or not,
noisy or not), the devices on it, the callers and what each one does, and when the port
is pulled out. The same seed always gives the same scenario, so a failing seed is
reproduced with ``AIORTU_TORTURE_SEED=<seed> pytest tests/torture``.

The register map every device shares (holding registers):

- ``OWN + k`` (k < 200) belongs to caller k: only caller k writes it, with
  :func:`encode` ``(k, sequence)``; it starts at 0.
- ``CONSTANT + a`` (a < 100) holds :func:`constant` ``(unit, a)`` and is never written.

A read of the first block returns, at each address, 0 or a value its owner wrote; a read
of the second returns exactly the constants of the unit asked. A reply meant for another
request (another unit, address or count) breaks one of the two.

Timing rules that keep every scenario inside what the master promises (see the
``Master`` docstring on late replies): a device's reply never comes later than the
late-reply guard after its request, queued requests included, so a stale reply always
ends before the next request begins to go out.
"""

from __future__ import annotations

import random
from dataclasses import dataclass

from aiortu.core.serial import LineSettings
from aiortu.testing import FaultPlan

__all__ = (
    "CONSTANT",
    "LOAD_MARGIN",
    "OWN",
    "Call",
    "Caller",
    "Device",
    "MasterScenario",
    "SlaveScenario",
    "constant",
    "encode",
    "master_scenario",
    "slave_scenario",
)

OWN = 0
"""First register of the callers' own block."""
MAX_CALLERS = 200
CONSTANT = 1000
"""First register of the constant block."""
CONSTANTS = 100
MAX_STEPS = 12
"""Steps per caller at most: the sequence numbers stay within one byte."""

LOAD_MARGIN = 0.1
"""Seconds added to every late-reply guard: on a loaded machine a slave's task may send
its reply that much later than its device model says, and a reply later than the guard
may be taken for the next request of the same shape (the master's documented limit)."""

BAUDRATES = (300, 1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200)
BEHAVIOURS = ("slow", "late", "dead", "wrong_unit")


def encode(caller: int, sequence: int) -> int:
    """The value caller *caller* writes at its *sequence*-th write (1-based, < 256)."""
    return caller << 8 | sequence


def constant(unit: int, offset: int) -> int:
    """The value of register ``CONSTANT + offset`` on *unit*."""
    return (unit * 251 + offset * 17 + 1) & 0xFFFF


@dataclass(frozen=True, slots=True)
class Device:
    """A unit on the line. *behaviour*: ``good`` (answers at once), ``slow`` (answers after
    *delay*, within the timeout), ``late`` (after *delay*, past the timeout), ``dead``
    (executes, never answers), ``wrong_unit`` (answers as unit *answer_as*)."""

    unit: int
    behaviour: str
    delay: float = 0.0
    answer_as: int = 0


@dataclass(frozen=True, slots=True)
class Call:
    """One call a caller makes, after *pause* seconds.

    *kind*: ``read_own`` (registers of the own block), ``read_constant``, ``write``
    (write_registers of the caller's own register), ``write_one`` (write_register),
    ``broadcast`` (broadcast write_register). *timeout* None uses the master's. *cancel*:
    ``none``, ``scope`` (another task cancels a scope around the call after
    *cancel_after* seconds) or ``move_on`` (``anyio.move_on_after(cancel_after)``).
    """

    kind: str
    unit: int
    address: int
    count: int
    timeout: float | None
    priority: int
    cancel: str
    cancel_after: float
    pause: float


@dataclass(frozen=True, slots=True)
class Caller:
    """Caller *index* makes its *calls* one after the other."""

    index: int
    calls: tuple[Call, ...]


@dataclass(frozen=True, slots=True)
class MasterScenario:
    """One storm against a master (see the module docstring).

    *line* is ``virtual`` or ``pty``; *baudrate* None runs the line unpaced. *unplugs*
    are the times (from the start) at which the master's port is pulled; it comes back
    *absent* seconds later.
    """

    seed: int
    line: str
    baudrate: int | None
    faults: FaultPlan | None
    devices: tuple[Device, ...]
    callers: tuple[Caller, ...]
    timeout: float
    retries: int
    late_reply_guard: float
    unplugs: tuple[float, ...]
    absent: float

    @property
    def settings(self) -> LineSettings:
        """The line settings of the master and the slaves."""
        return LineSettings(self.baudrate or 115200, parity="N")

    @property
    def operations(self) -> int:
        """How many calls the callers make."""
        return sum(len(caller.calls) for caller in self.callers)

    def describe(self) -> str:
        """One line that says what the scenario is, for failure messages and the soak."""
        behaviours = ",".join(f"{d.unit}:{d.behaviour}" for d in self.devices)
        return (
            f"seed={self.seed} line={self.line} baud={self.baudrate or 'unpaced'} "
            f"callers={len(self.callers)} calls={self.operations} timeout={self.timeout:.3f} "
            f"retries={self.retries} guard={self.late_reply_guard:.3f} "
            f"noisy={self.faults is not None} unplugs={len(self.unplugs)} devices=[{behaviours}]"
        )


@dataclass(frozen=True, slots=True)
class SlaveScenario:
    """One storm against a slave: *rogues* other masters send *frames* each (garbage,
    requests to other units and to ours, broadcasts, other slaves' replies) while a
    master checks the slave's answers; the slave's serve task is cancelled at each of
    *restarts* (seconds from the start; with *in_request*, at the first request after
    it, from inside the request) and a new slave takes over the same stores. A
    before-request hook sleeps *slow_hook* seconds (0: no hook, the fast paths serve).
    *line* is ``virtual`` (a VirtualBus) or ``pty`` (a PtyBus: every party opens its
    port as a serial device, and the slave answers from the read callback)."""

    seed: int
    baudrate: int | None
    units: tuple[int, ...]
    rogues: int
    frames: int
    restarts: tuple[float, ...]
    in_request: bool
    slow_hook: float
    checks: int
    line: str = "virtual"

    @property
    def settings(self) -> LineSettings:
        """The line settings."""
        return LineSettings(self.baudrate or 115200, parity="N")

    def describe(self) -> str:
        """One line that says what the scenario is."""
        return (
            f"seed={self.seed} slave line={self.line} baud={self.baudrate or 'unpaced'} "
            f"units={self.units} "
            f"rogues={self.rogues}x{self.frames} restarts={len(self.restarts)} "
            f"in_request={self.in_request} "
            f"slow_hook={self.slow_hook:.3f} checks={self.checks}"
        )


def _line(generator: random.Random) -> tuple[str, int | None]:
    """The line and its baud rate: mostly unpaced in memory, some paced, some on ptys."""
    draw = generator.random()
    if draw < 0.62:
        return "virtual", None
    if draw < 0.85:
        return "virtual", generator.choice(BAUDRATES)
    if draw < 0.95:
        return "pty", None
    return "pty", generator.choice(BAUDRATES[-3:])


def _reply_time(settings: LineSettings | None) -> float:
    """Seconds the biggest reply here takes after its request has left the wire: the
    slave's t3.5, then 11 bytes (a read of three registers); 0 on an unpaced line."""
    if settings is None:
        return 0.0
    return settings.t3_5 + settings.wire_time(11)


def _devices(
    generator: random.Random, base: float, timeout: float, late: bool
) -> tuple[Device, ...]:
    """Unit 1 always good; up to four odd devices on units 2..; a few more good ones."""
    devices = [Device(1, "good")]
    unit = 2
    behaviours = BEHAVIOURS if late else tuple(b for b in BEHAVIOURS if b != "late")
    for _ in range(generator.randint(0, 4)):
        behaviour = generator.choice(behaviours)
        if behaviour == "slow":
            devices.append(Device(unit, "slow", generator.uniform(0.05, 0.4) * base))
        elif behaviour == "late":
            devices.append(Device(unit, "late", timeout + generator.uniform(0.3, 1.0) * base))
        elif behaviour == "wrong_unit":
            devices.append(Device(unit, "wrong_unit", answer_as=generator.randint(100, 120)))
        else:
            devices.append(Device(unit, "dead"))
        unit += 1
    for _ in range(generator.randint(0, 2)):
        devices.append(Device(unit, "good"))
        unit += 1
    return tuple(devices)


def _call(generator: random.Random, index: int, line: _Line) -> Call:
    timeout, paced = line.timeout, line.paced
    kind = generator.choices(
        ("read_own", "read_constant", "write", "write_one", "broadcast"), (4, 3, 3, 2, 1)
    )[0]
    # Calls to odd devices (or to a unit nobody answers to) hold the line for whole
    # timeouts and guards: few of them keep a scenario within seconds.
    if generator.random() < line.odd_share:
        unit = generator.choice(line.odd_units) if line.odd_units else 99
    else:
        unit = generator.choice(line.good_units)
    count = generator.randint(1, 3 if paced else 12)
    if kind == "read_own":
        address = OWN + generator.randrange(0, MAX_CALLERS - count)
    elif kind == "read_constant":
        address = CONSTANT + generator.randrange(0, CONSTANTS - count)
    else:
        address, count = OWN + index, 1
    cancel = generator.choices(("none", "scope", "move_on"), (6, 2, 2))[0]
    # Cancellations land anywhere: before the call starts, queued, on the wire, waiting
    # for the reply, or after it came back.
    cancel_after = generator.choice((0.0, 1e-4, generator.uniform(0, 3 * timeout)))
    return Call(
        kind=kind,
        unit=unit,
        address=address,
        count=count,
        timeout=None if generator.random() < 0.6 else generator.uniform(0.8, 1.5) * timeout,
        priority=generator.choice((0, 0, 0, 1, -1, 5)),
        cancel=cancel,
        cancel_after=cancel_after,
        pause=generator.choice((0.0, 0.0, generator.uniform(0, timeout))),
    )


def _troubles(
    generator: random.Random, seed: int, line: str, timeout: float
) -> tuple[FaultPlan | None, tuple[float, ...]]:
    """Noise on the line, and when the master's port is pulled (in memory only)."""
    faults = None
    if line == "virtual" and generator.random() < 0.25:
        faults = FaultPlan(
            bit_error_rate=generator.choice((1e-4, 3e-4)),
            drop_rate=generator.choice((0.0, 3e-4)),
            seed=seed,
        )
    unplugs: tuple[float, ...] = ()
    if line == "virtual" and generator.random() < 0.2:
        unplugs = tuple(
            sorted(generator.uniform(0, 4 * timeout) for _ in range(generator.randint(1, 2)))
        )
    return faults, unplugs


@dataclass(frozen=True, slots=True)
class _Line:
    """What drawing a call needs to know about the line."""

    timeout: float
    paced: bool
    good_units: list[int]
    odd_units: list[int]
    odd_share: float


def master_scenario(seed: int) -> MasterScenario:
    """The master scenario of *seed*."""
    generator = random.Random(seed)
    line, baudrate = _line(generator)
    settings = LineSettings(baudrate, parity="N") if baudrate else None
    slow_line = baudrate is not None and baudrate < 9600
    base = generator.uniform(0.02, 0.06) * (3 if line == "pty" else 1)
    timeout = base + 1.5 * _reply_time(settings)
    retries = generator.randint(0, 1 if slow_line else 2)
    devices = _devices(generator, base, timeout, late=not slow_line)
    # The guard covers the latest reply: a late device's, behind its own queued retries
    # (each of those requests and replies on the wire too), plus LOAD_MARGIN.
    transaction = settings.transaction_time(11, 11) if settings is not None else 0.0
    slowest = max(device.delay for device in devices) + transaction
    guard = (retries + 1) * slowest + LOAD_MARGIN
    if slow_line:
        callers, steps = generator.randint(1, 2), 2
    elif baudrate is not None or line == "pty":
        callers, steps = generator.randint(1, 12), 3
    else:
        callers = generator.choice((1, 3, 10, 30, 60, 120, 200))
        steps = max(1, min(MAX_STEPS, 300 // callers))
    odd = [device.unit for device in devices if device.behaviour != "good"]
    draw = _Line(
        timeout=timeout,
        paced=baudrate is not None,
        good_units=[device.unit for device in devices if device.behaviour == "good"],
        odd_units=[*odd, 99],
        odd_share=min(0.3, 6 / (callers * (steps + 1) / 2)),
    )
    population = tuple(
        Caller(
            index, tuple(_call(generator, index, draw) for _ in range(generator.randint(1, steps)))
        )
        for index in range(callers)
    )
    faults, unplugs = _troubles(generator, seed, line, timeout)
    return MasterScenario(
        seed=seed,
        line=line,
        baudrate=baudrate,
        faults=faults,
        devices=devices,
        callers=population,
        timeout=timeout,
        retries=retries,
        late_reply_guard=guard,
        unplugs=unplugs,
        absent=generator.uniform(0.005, 2 * timeout),
    )


def slave_scenario(seed: int) -> SlaveScenario:
    """The slave scenario of *seed*."""
    generator = random.Random(seed)
    baudrate = None if generator.random() < 0.7 else generator.choice(BAUDRATES[4:])
    restarts = tuple(
        sorted(generator.uniform(0, 0.3) for _ in range(generator.choice((0, 0, 1, 2))))
    )
    return SlaveScenario(
        seed=seed,
        baudrate=baudrate,
        units=tuple(sorted(generator.sample(range(1, 12), generator.randint(1, 3)))),
        rogues=generator.randint(1, 4),
        frames=generator.randint(5, 40),
        restarts=restarts,
        in_request=generator.random() < 0.5,
        slow_hook=generator.choice((0.0, 0.0, generator.uniform(0.001, 0.01))),
        checks=generator.randint(5, 30),
        # Drawn last, so that the draws above stay those of the seeds reported before.
        line="pty" if generator.random() < 0.25 else "virtual",
    )
