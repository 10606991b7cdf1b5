"""The bridge: lines polled by their devices' profiles, values and health published to an
MQTT broker in a topic layout, writes taken from it.

    config = aiortu.bridge.load_config("bridge.toml")
    async with aiortu.bridge.Bridge(config) as bridge:
        await bridge.wait()          # until cancelled

Each line has its master (failing fast on offline units, which it probes now and then) and a
[`ProfilePoller`][aiortu.master.ProfilePoller] over its devices. After each poll class of a
device is read, the values that changed (or all of them, for points published every poll)
and any change of the unit's health become messages in the outbox, which the broker session
delivers in order whenever the broker is there. Commands from the broker go through one
writer task: parsed, checked against the profile, written, read back and published; anything
refused or failed goes to the error topic, and the bridge goes on.
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Self

import anyio
import anyio.abc

from aiortu._log import get_logger
from aiortu.bridge._config import VIRTUAL_PORT, BridgeConfig, LineConfig
from aiortu.bridge._config_file import load_config
from aiortu.bridge._layouts import make_layout
from aiortu.bridge._outbox import Message, Outbox
from aiortu.bridge._packets import Publish
from aiortu.bridge._payloads import CommandError, parse_command
from aiortu.bridge._session import BrokerSession, SessionHooks
from aiortu.bridge._state import Command, DeviceState, Layout, device_states
from aiortu.core.model import Value
from aiortu.errors import InvalidValue, ModbusError
from aiortu.line import loop_clock
from aiortu.master import Device, Master, ProfilePoller, Reading, UnitState, open_master
from aiortu.slave import ProfileStore, Slave
from aiortu.testing import VirtualBus

__all__ = ("Bridge", "BridgeStats", "run")

_log = get_logger(__name__)
_MISSING = object()


@dataclass(slots=True)
class BridgeStats:
    """What the bridge did: `readings` taken from the pollers, `messages` made for the
    broker (`values` of them carrying a point's value), `writes` done from commands and
    `write_errors` refused or failed."""

    readings: int = 0
    messages: int = 0
    values: int = 0
    writes: int = 0
    write_errors: int = 0


class Bridge:
    """The bridge of `config` (see the module docstring); an async context manager.

    Entering connects to the broker once (a refused login, or a certificate that cannot be
    loaded or does not check, raises [`BrokerError`][aiortu.bridge.BrokerError]; an
    unreachable broker is logged, and the bridge polls and buffers until it is there), opens
    the lines and starts polling.
    """

    def __init__(self, config: BridgeConfig) -> None:
        self.config = config
        self.outbox = Outbox(config.max_messages, config.max_bytes)
        """The messages waiting for the broker."""
        self.layout: Layout = make_layout(config.topics)
        self.devices = device_states(config)
        """Each device's state, in the configuration's order."""
        self._by_name = {device.name: device for device in self.devices}
        self.layout.bind(self.devices)
        self.session = BrokerSession(config.broker, self.outbox, SessionHooks(
            will=self.layout.will, subscriptions=self.layout.subscriptions,
            on_connect=self._on_connect, on_publish=self._on_publish,
            prepare=self.layout.prepare,
        ))  # fmt: skip
        """The connection to the broker."""
        self.stats = BridgeStats()
        self.simulated: dict[str, ProfileStore] = {}
        """The simulated devices of `virtual` lines, by device name (set a value to see it
        published)."""
        self._handles: dict[str, Device] = {}
        self._state_of: dict[Device, DeviceState] = {}
        self._send, self._receive = anyio.create_memory_object_stream[Command](64)
        self._stack: contextlib.AsyncExitStack | None = None
        self._clock: Callable[[], float] = anyio.current_time
        """The backend's clock (`Message.created`), as read where no task runs: a pushed
        session hands commands over from the event loop's callback."""

    async def __aenter__(self) -> Self:
        self._clock = loop_clock()
        async with contextlib.AsyncExitStack() as stack:
            try:
                await self.session.connect()
            except (OSError, TimeoutError) as error:
                _log.warning("broker %s cannot be reached (%s): polling and buffering until it can",
                             self.config.broker.url, error or type(error).__name__)  # fmt: skip
            stack.push_async_callback(self.session.close)
            pollers = []
            for line in self.config.lines:
                master = await stack.enter_async_context(self._open_line(line))
                devices = [self._device(master, state) for state in self._states_of(line)]
                pollers.append(ProfilePoller(devices, on_read=self._publish_read,
                                             max_pending=0))  # fmt: skip
            tasks = await stack.enter_async_context(anyio.create_task_group())
            stack.callback(tasks.cancel_scope.cancel)
            tasks.start_soon(self.session.run, name="aiortu bridge broker session")
            tasks.start_soon(self._writer, name="aiortu bridge writer")
            for poller, line in zip(pollers, self.config.lines, strict=True):
                tasks.start_soon(self._poll, poller, line, name="aiortu bridge poller")
            self._stack = stack.pop_all()
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> bool | None:  # fmt: skip
        stack, self._stack = self._stack, None
        if stack is None:
            return None
        return await stack.__aexit__(exc_type, exc, traceback)

    async def wait(self) -> None:
        """Run until cancelled."""
        await anyio.sleep_forever()

    async def _poll(self, poller: ProfilePoller, line: LineConfig) -> None:
        """Poll `line` for good: a line lost (a gateway restarted, an adapter unplugged)
        marks its devices offline until the master has it back."""
        while True:
            try:
                await poller.run()
            except* ModbusError as group:  # the poller's own task group wraps it
                _log.warning("line %s: %s; its devices are offline until it is back", line.port,
                             group.exceptions[0])  # fmt: skip
                self._line_lost(line)
            await anyio.sleep(1.0)

    def _line_lost(self, line: LineConfig) -> None:
        now = self._clock()
        for state in self._states_of(line):
            if state.health is not UnitState.OFFLINE:
                state.health = UnitState.OFFLINE
                self._put(self.layout.health(state, now))

    def _states_of(self, line: LineConfig) -> list[DeviceState]:
        return [self._by_name[device.name] for device in line.devices]

    def _device(self, master: Master, state: DeviceState) -> Device:
        device = Device(master, state.config.unit, state.config.profile)
        self._handles[state.name] = device
        self._state_of[device] = state
        return device

    @contextlib.asynccontextmanager
    async def _open_line(self, line: LineConfig) -> AsyncIterator[Master]:
        options = {"fail_fast_offline": True, **line.options}
        if line.port != VIRTUAL_PORT:
            async with open_master(line.port, **options) as master:
                yield master
            return
        for key in ("baudrate", "parity", "stopbits", "bytesize"):
            options.pop(key, None)
        bus = VirtualBus(2)
        stores = {d.unit: ProfileStore(d.profile) for d in line.devices}
        self.simulated.update({d.name: stores[d.unit] for d in line.devices})
        async with Slave(bus.endpoints[1], stores), Master(bus.endpoints[0], **options) as master:
            yield master

    def _publish_read(self, device: Device, batch: dict[str, Reading]) -> None:
        """The poller's callback: what changed in a read of one poll class of `device` (and
        its unit's health, if that changed) goes to the outbox."""
        state = self._state_of[device]
        self.stats.readings += len(batch)
        now = self._clock()
        config, values, published = state.config, state.values, state.published
        if not state.complete:
            state.seen.update(name for name in batch if name in published)
        every = published if config.publish == "every" else config.every_poll
        changed: dict[str, Value] = {}
        for name, reading in batch.items():
            value = reading.value
            if (reading.error is None and name in published
                    and (name in every or values.get(name, _MISSING) != value)):  # fmt: skip
                changed[name] = values[name] = value
        messages: list[Message] = []
        health = device.master.unit_stats(config.unit).state
        if health is not state.health:
            state.health = health
            _log.info("device %s is %s", state.name, health.value)
            messages += self.layout.health(state, now)
        messages += self.layout.values(state, changed, now)
        self.stats.values += len(changed)
        self._put(messages)

    def _put(self, messages: list[Message]) -> None:
        self.outbox.put_all(messages)
        self.stats.messages += len(messages)

    def _on_connect(self) -> list[Message]:
        return self.layout.on_connect(self.devices, self.outbox.dropped, self._clock())

    def _on_publish(self, publish: Publish) -> None:
        now = self._clock()
        commands, messages = self.layout.command(publish, self.devices, now)
        self._put(messages)
        for command in commands:
            try:
                self._send.send_nowait(command)
            except anyio.WouldBlock:
                self._refuse(command, "too many writes are waiting; send it again later")

    def _refuse(self, command: Command, reason: str) -> None:
        self.stats.write_errors += 1
        _log.warning("write of %s.%s refused: %s", command.device, command.point, reason)
        self._put([self.layout.error(command.device, command.point, command.payload, reason,
                                     self._clock())])  # fmt: skip

    async def _writer(self) -> None:
        async for command in self._receive:
            reason = await self._write(command)
            if reason is not None:
                self._refuse(command, reason)

    async def _write(self, command: Command) -> str | None:
        """Do one write; return why it was refused or failed (None: done)."""
        state = self._by_name.get(command.device)
        device = self._handles.get(command.device)
        if state is None or device is None:
            return f"no device named {command.device!r}"
        point = next((p for p in state.points if p.name == command.point), None)
        if point is None:
            return f"device {state.name!r} publishes no point named {command.point!r}"
        if not point.writable:
            return f"point {point.name!r} is read-only"
        try:
            value = command.value if command.typed else parse_command(point, command.payload)
            await device.write(point.name, value)
            reading = (await device.read_points([point.name]))[point.name]
        except CommandError as error:
            return f"point {point.name!r}: {error}"
        except InvalidValue as error:
            return f"refused: {str(error).removeprefix(f'{point_source(state)}: ')}"
        except ModbusError as error:
            return f"point {point.name!r}: the write failed: {error}"
        self.stats.writes += 1
        if reading.error is None:
            state.values[point.name] = reading.value
            self._put(self.layout.values(state, {point.name: reading.value}, self._clock()))
        return None


def point_source(state: DeviceState) -> str:
    """The file of `state`'s profile, as the profile's errors name it."""
    return state.config.profile.source


async def run(config: BridgeConfig | str | Path) -> None:
    """Run the bridge of `config` (a [`BridgeConfig`][aiortu.bridge.BridgeConfig] or a TOML
    file) until cancelled."""
    if not isinstance(config, BridgeConfig):
        config = load_config(config)
    async with Bridge(config) as bridge:
        await bridge.wait()
