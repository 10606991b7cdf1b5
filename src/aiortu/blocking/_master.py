"""The blocking master: [`Master`][aiortu.master.Master], its unit handles and its broadcast
handle, each method made from the async one by a table of one line per method."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Coroutine
from contextlib import AbstractAsyncContextManager
from types import TracebackType
from typing import Any, Concatenate, ParamSpec, Protocol, Self, TypeVar, TypeVarTuple

from aiortu._derived import derive
from aiortu.blocking._portal import Running
from aiortu.master import BroadcastHandle, BroadcastMethod, Master, UnitHandle, UnitStats

__all__ = (
    "BlockingBroadcastHandle",
    "BlockingMaster",
    "BlockingUnitHandle",
    "blocking_master",
)

_P = ParamSpec("_P")
_R = TypeVar("_R")
_Ts = TypeVarTuple("_Ts")


class _Blocking:
    """What the made methods call through: the running master and the async object whose
    method each one runs (the master, a unit handle, the broadcast handle)."""

    _running: Running[Master]
    _target: Any

    def __init_subclass__(cls) -> None:
        for name, member in vars(cls).items():
            if callable(member) and getattr(member, "__qualname__", None) == name:  # made
                member.__qualname__ = f"{cls.__name__}.{name}"


def _blocking(
    method: Callable[Concatenate[Any, _P], Coroutine[Any, Any, _R]],
) -> Callable[Concatenate[_Blocking, _P], _R]:
    """The blocking form of the async `method`: the same call, run in the loop, waited for."""
    name = method.__name__

    def call(self: _Blocking, /, *args: _P.args, **kwargs: _P.kwargs) -> _R:
        result: _R = self._running.call(getattr(self._target, name), *args, **kwargs)
        return result

    derive(call, method, None)
    return call


def _in_loop(
    method: Callable[Concatenate[Any, _P], _R],
) -> Callable[Concatenate[_Blocking, _P], _R]:
    """The blocking form of a plain `method` of the master: run in the loop, whose state it
    reads or changes."""
    name = method.__name__

    def call(self: _Blocking, /, *args: _P.args, **kwargs: _P.kwargs) -> _R:
        result: _R = self._running.call(getattr(self._target, name), *args, **kwargs)
        return result

    derive(call, method, None)
    return call


class _BlockingBroadcastMethod(Protocol[*_Ts]):
    def __call__(self, *args: *_Ts, priority: int = 0) -> None: ...


def _blocking_broadcast(
    method: BroadcastMethod[*_Ts],
) -> _BlockingBroadcastMethod[*_Ts]:
    """The blocking form of a broadcast `method`."""
    name = method.__name__  # type: ignore[attr-defined]  # a function, whose type is the protocol

    def call(self: _Blocking, /, *args: *_Ts, priority: int = 0, **named: Any) -> None:
        self._running.call(getattr(self._target, name), *args, priority=priority, **named)

    derive(call, method, None)
    return call  # type: ignore[return-value]  # its call is the protocol's


class BlockingBroadcastHandle(_Blocking):
    """[`BroadcastHandle`][aiortu.master.BroadcastHandle] without async: `master.broadcast`."""

    def __init__(self, running: Running[Master]) -> None:
        self._running = running
        self._target = running.value.broadcast

    write_coil = _blocking_broadcast(BroadcastHandle.write_coil)
    write_register = _blocking_broadcast(BroadcastHandle.write_register)
    write_coils = _blocking_broadcast(BroadcastHandle.write_coils)
    write_registers = _blocking_broadcast(BroadcastHandle.write_registers)
    mask_write_register = _blocking_broadcast(BroadcastHandle.mask_write_register)
    write_file_record = _blocking_broadcast(BroadcastHandle.write_file_record)


class BlockingUnitHandle(_Blocking):
    """[`UnitHandle`][aiortu.master.UnitHandle] without async: `master.slave(unit)`."""

    def __init__(self, master: BlockingMaster, unit: int) -> None:
        self.master = master
        """The blocking master."""
        self.unit = unit
        """The unit address."""
        self._running = master._running
        self._target = master.master.slave(unit)

    read_coils = _blocking(UnitHandle.read_coils)
    read_discrete_inputs = _blocking(UnitHandle.read_discrete_inputs)
    read_holding_registers = _blocking(UnitHandle.read_holding_registers)
    read_input_registers = _blocking(UnitHandle.read_input_registers)
    write_coil = _blocking(UnitHandle.write_coil)
    write_coils = _blocking(UnitHandle.write_coils)
    write_register = _blocking(UnitHandle.write_register)
    write_registers = _blocking(UnitHandle.write_registers)
    mask_write_register = _blocking(UnitHandle.mask_write_register)
    read_write_registers = _blocking(UnitHandle.read_write_registers)
    read_fifo_queue = _blocking(UnitHandle.read_fifo_queue)
    read_file_record = _blocking(UnitHandle.read_file_record)
    write_file_record = _blocking(UnitHandle.write_file_record)
    read_exception_status = _blocking(UnitHandle.read_exception_status)
    diagnostics = _blocking(UnitHandle.diagnostics)
    get_comm_event_counter = _blocking(UnitHandle.get_comm_event_counter)
    get_comm_event_log = _blocking(UnitHandle.get_comm_event_log)
    report_server_id = _blocking(UnitHandle.report_server_id)
    read_device_identification = _blocking(UnitHandle.read_device_identification)
    execute = _blocking(UnitHandle.execute)
    read_value = _blocking(UnitHandle.read_value)
    write_value = _blocking(UnitHandle.write_value)
    read_float32 = _blocking(UnitHandle.read_float32)
    read_int32 = _blocking(UnitHandle.read_int32)
    read_uint32 = _blocking(UnitHandle.read_uint32)
    write_float32 = _blocking(UnitHandle.write_float32)
    write_int32 = _blocking(UnitHandle.write_int32)
    write_uint32 = _blocking(UnitHandle.write_uint32)
    read_string = _blocking(UnitHandle.read_string)
    write_string = _blocking(UnitHandle.write_string)
    read_reference = _blocking(UnitHandle.read_reference)


class BlockingMaster(_Blocking):
    """[`Master`][aiortu.master.Master] without async: every method takes the same arguments
    and returns what the async one returns, once done; a context manager.

    Made by [`open_master`][aiortu.blocking.open_master] or
    [`start_master`][aiortu.blocking.start_master], already open. Any number of threads may call
    it at once: their requests queue on the line as the async callers' do. Each call ends
    within its `timeout=` (the response timeout, per attempt) times the attempts, plus its wait
    for the line. [`close`][aiortu.blocking.BlockingMaster.close] works from any thread; calls
    still waiting then raise [`ConnectionLost`][aiortu.errors.ConnectionLost], as later ones do.
    """

    def __init__(self, running: Running[Master]) -> None:
        self._running = running
        self._target = running.value
        self.master = running.value
        """The async master, which runs in the blocking API's event loop thread: read its
        attributes here, call it from that loop only."""
        self.broadcast = BlockingBroadcastHandle(running)
        """The writes that may go to every unit at once (unit 0); no reply is awaited."""

    def slave(self, unit: int) -> BlockingUnitHandle:
        """A handle on `unit` (1..247; 0..255 over Modbus TCP): the master's methods without
        the unit, typed values."""
        return BlockingUnitHandle(self, unit)

    @property
    def connected(self) -> bool:
        """Whether the line is up: False while reconnecting and once failed or closed."""
        return self.master.connected

    @property
    def statistics(self) -> dict[int, UnitStats]:
        """A snapshot of the master's [`UnitStats`][aiortu.master.UnitStats] by unit address,
        for the units used so far, taken in the loop (the loop goes on counting)."""
        snapshot: dict[int, UnitStats] = self._running.call(_statistics, self.master)
        return snapshot

    @property
    def closed(self) -> bool:
        """Whether [`close`][aiortu.blocking.BlockingMaster.close] was called."""
        return self._running.closed

    def close(self) -> None:
        """Close the master and its port, from any thread (at most once; again does nothing)."""
        self._running.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    read_coils = _blocking(Master.read_coils)
    read_discrete_inputs = _blocking(Master.read_discrete_inputs)
    read_holding_registers = _blocking(Master.read_holding_registers)
    read_input_registers = _blocking(Master.read_input_registers)
    write_coil = _blocking(Master.write_coil)
    write_coils = _blocking(Master.write_coils)
    write_register = _blocking(Master.write_register)
    write_registers = _blocking(Master.write_registers)
    mask_write_register = _blocking(Master.mask_write_register)
    read_write_registers = _blocking(Master.read_write_registers)
    read_fifo_queue = _blocking(Master.read_fifo_queue)
    read_file_record = _blocking(Master.read_file_record)
    write_file_record = _blocking(Master.write_file_record)
    read_exception_status = _blocking(Master.read_exception_status)
    diagnostics = _blocking(Master.diagnostics)
    get_comm_event_counter = _blocking(Master.get_comm_event_counter)
    get_comm_event_log = _blocking(Master.get_comm_event_log)
    report_server_id = _blocking(Master.report_server_id)
    read_device_identification = _blocking(Master.read_device_identification)
    execute = _blocking(Master.execute)
    request = _blocking(Master.request)
    send_without_reply = _blocking(Master.send_without_reply)
    unit_stats = _in_loop(Master.unit_stats)
    is_online = _in_loop(Master.is_online)
    set_min_turnaround = _in_loop(Master.set_min_turnaround)


def _statistics(master: Master) -> dict[int, UnitStats]:
    return {unit: dataclasses.replace(stats) for unit, stats in master.statistics.items()}


def blocking_master(
    opener: Callable[_P, AbstractAsyncContextManager[Master]], doc: str
) -> Callable[_P, BlockingMaster]:
    """A function that takes `opener`'s arguments and returns a
    [`BlockingMaster`][aiortu.blocking.BlockingMaster] on the master it opens."""

    def open_blocking(*args: _P.args, **kwargs: _P.kwargs) -> BlockingMaster:
        return BlockingMaster(Running(lambda: opener(*args, **kwargs), "the master"))

    derive(open_blocking, opener, None, doc=doc, returns="BlockingMaster")
    return open_blocking
