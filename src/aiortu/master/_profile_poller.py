"""Polling devices described by profiles: each poll class of each device on its own interval.

    meters = [aiortu.Device(master, unit, profile) for unit in (1, 2, 3)]
    async with aiortu.ProfilePoller(meters) as poller:
        async for reading in poller:
            print(reading.unit, reading.name, reading.value, reading.unit_of_measurement)

A cycle of an interval reads, device after device, the poll classes with that interval
([`Device.read`][aiortu.master.Device.read]: refused merged reads split and remembered, one
timeout per silent unit) and delivers one [`Reading`][aiortu.master.Reading] per point, to the
`on_reading` callbacks and to `async for`; a consumer more than `max_pending` readings behind
loses the oldest, counted in [`ProfilePoller.dropped`][aiortu.master.ProfilePoller.dropped].
The `on_read` callbacks get each read whole instead: the device and its readings of one poll
class, by name; with `max_pending=0`, readings go to the callbacks only (`async for` gets
none), which spares a caller that wants whole reads the work of each reading.
Units the master marks offline fail fast there, so dead devices do not stall the bus.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable, Iterable

import anyio
import anyio.abc

from aiortu.errors import InvalidValue
from aiortu.master._background import BackgroundPoll
from aiortu.master._device import Device, Reading

__all__ = ("ProfilePoller",)

ReadingCallback = Callable[[Reading], object]
"""Called with every reading (a plain or an async function)."""

ReadCallback = Callable[[Device, dict[str, Reading]], object]
"""Called with a device and its readings of one poll class, by name, once they are all read
(a plain or an async function)."""


class ProfilePoller(BackgroundPoll[Reading]):
    """Polls `devices` by their profiles' poll classes (see the module docstring); an async
    context manager and an async iterator of readings."""

    _task_name = "aiortu profile poller"

    def __init__(
        self,
        devices: Iterable[Device],
        *,
        on_reading: ReadingCallback | Iterable[ReadingCallback] | None = None,
        on_read: ReadCallback | None = None,
        max_pending: int = 1024,
    ) -> None:
        self.devices = tuple(devices)
        if not self.devices:
            raise InvalidValue("devices", self.devices, "at least one device")
        if isinstance(max_pending, bool) or not isinstance(max_pending, int) or max_pending < 0:
            raise InvalidValue("max_pending", max_pending, "an integer >= 0")
        groups: dict[float, list[tuple[Device, str]]] = {}
        for device in self.devices:
            for poll_class, interval in device.profile.poll_classes.items():
                if device.profile.points_of(poll_class):
                    groups.setdefault(interval, []).append((device, poll_class))
        self._groups = sorted(groups.items())
        self._callbacks: list[ReadingCallback] = (
            [on_reading] if callable(on_reading) else list(on_reading or ())
        )
        self._read_callbacks = [] if on_read is None else [on_read]
        self._streaming = max_pending > 0
        self._open_stream(max_pending)
        self.cycles = 0
        """Cycles run, every interval counted."""
        self.dropped = 0
        """Readings dropped because the iterating consumer fell behind."""

    def on_reading(self, callback: ReadingCallback) -> Callable[[], None]:
        """Call `callback` with every reading from now on; return a function that stops it."""
        self._callbacks.append(callback)
        return lambda: self._callbacks.remove(callback)

    async def poll_once(self) -> list[Reading]:
        """Run one cycle of every interval now; return its readings (also delivered)."""
        readings: list[Reading] = []
        for _, members in self._groups:
            readings += await self._cycle(members)
        return readings

    async def run(self, *, cycles: int | None = None, duration: float | None = None) -> None:
        """Poll until cancelled, `cycles` cycles of the shortest interval, or `duration`
        seconds; then end the stream of readings."""
        try:
            with anyio.move_on_after(math.inf if duration is None else duration):
                async with anyio.create_task_group() as tasks:
                    for interval, members in self._groups[1:]:
                        tasks.start_soon(self._loop, interval, members, None)
                    await self._loop(*self._groups[0], cycles)
                    tasks.cancel_scope.cancel()
        finally:
            self._send.close()

    async def _loop(
        self, interval: float, members: list[tuple[Device, str]], cycles: int | None
    ) -> None:
        clock = anyio.current_time
        next_start = clock()
        done = 0
        while cycles is None or done < cycles:
            await self._cycle(members)
            done += 1
            next_start = max(next_start + interval, clock())
            if cycles is None or done < cycles:
                await anyio.sleep(max(0.0, next_start - clock()))

    async def _cycle(self, members: list[tuple[Device, str]]) -> list[Reading]:
        readings: list[Reading] = []
        for device, poll_class in members:
            read = await device.read(poll_class)
            readings += read.values()
            for on_read in self._read_callbacks:
                result = on_read(device, read)
                if inspect.isawaitable(result):
                    await result
            if self._callbacks or self._streaming:  # else nobody wants them one by one
                for reading in read.values():
                    await self._deliver(reading)
        self.cycles += 1
        return readings

    async def _deliver(self, reading: Reading) -> None:
        for callback in list(self._callbacks):
            result = callback(reading)
            if inspect.isawaitable(result):
                await result
        if self._streaming:
            self._publish(reading)
