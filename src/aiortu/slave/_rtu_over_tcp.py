"""RTU (or ASCII) framing over TCP, listening: one device for every connection, for serial
device servers that connect in.

[`RtuOverTcpServer`][aiortu.slave.RtuOverTcpServer] is the
[`ModbusTcpServer`][aiortu.slave.ModbusTcpServer] with a server framing the gateway uses
([`RtuFraming`][aiortu.transport.RtuFraming], or
[`AsciiFraming`][aiortu.transport.AsciiFraming]) and a serial device's rules: every connection
reaches the same device (one state machine, its counters, its listen-only mode), a unit it
does not serve is silent, unit 0 is a broadcast, and the serial-line codes (07, 08, 0B, 0C, 11)
are served. The limits are the Modbus TCP server's: `max_connections`, and `idle_timeout` for
a connection that sends nothing, or reads no reply, for that long.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping

from aiortu.core.ascii import DEFAULT_ASCII_TIMEOUT
from aiortu.core.model import AsyncDataStore, DataStore
from aiortu.core.rtu import TimingMode
from aiortu.core.serial import LineSettings
from aiortu.errors import InvalidValue
from aiortu.slave._dispatch import TraceCallback
from aiortu.slave._handlers import Handler
from aiortu.slave._tcp_server import (
    DEFAULT_IDLE_TIMEOUT,
    DEFAULT_MAX_CONNECTIONS,
    ModbusTcpServer,
)
from aiortu.transport import AsciiFraming, RtuFraming

__all__ = ("RtuOverTcpServer",)


class RtuOverTcpServer(ModbusTcpServer):
    """RTU frames over TCP, listening (see the module docstring): the connections share one
    device, as a serial device server's masters share its line.

    A frame's length comes from its function code; a frame of a code whose length it does not
    tell ends after 20 ms of silence; after noise (a bad CRC) the framing finds the next valid
    frame in what it holds, and it never holds more than 256 bytes between reads. With
    `framing` `"ascii"` the connections speak Modbus ASCII instead (`ascii_timeout` the longest
    gap inside a frame, 1 s by default). `settings` and `timing` are accepted for the serial
    line the frames came from, and do not change what is answered (a TCP connection has no
    character timing). `trace` sees `("received", frame)` and `("sent", frame)`, in the
    connection's framing. At most `max_connections` at once; more are closed at once. A
    connection that sends nothing for `idle_timeout` seconds (120 by default) is closed, and so
    is one whose reply cannot be written for as long (it reads nothing), as on Modbus TCP. A
    serial device server that connects in and stays quiet while no master polls is closed too,
    and must connect again; `idle_timeout=math.inf` keeps such connections open.
    """

    _name = "RTU over TCP"

    def __init__(
        self,
        units: Mapping[int, DataStore | AsyncDataStore],
        settings: LineSettings | None = None,
        *,
        timing: TimingMode | str = TimingMode.TOLERANT,
        handlers: Mapping[int, Handler] | None = None,
        trace: TraceCallback | None = None,
        max_connections: int = DEFAULT_MAX_CONNECTIONS,
        idle_timeout: float = DEFAULT_IDLE_TIMEOUT,
        framing: str = "rtu",
        ascii_timeout: float | None = None,
    ) -> None:
        if framing not in ("rtu", "ascii"):
            raise InvalidValue("framing", framing, "'rtu' or 'ascii'")
        if ascii_timeout is not None and framing != "ascii":
            raise InvalidValue("ascii_timeout", ascii_timeout, "given with framing='ascii' only")
        if framing == "ascii":
            timeout = DEFAULT_ASCII_TIMEOUT if ascii_timeout is None else ascii_timeout
            self._new_framing = functools.partial(AsciiFraming, timeout)
        else:
            self._new_framing = RtuFraming
        self.framing = framing
        """`rtu` or `ascii`: the framing the connections speak."""
        super().__init__(
            units,
            handlers=handlers,
            unit_aliases={},
            answer_unknown_units=False,
            serial_line_codes=True,
            max_connections=max_connections,
            idle_timeout=idle_timeout,
            trace=trace,
        )
        self.settings = settings
        """The line settings given (they change nothing on TCP)."""
        self.timing = TimingMode(timing)
        """The timing mode given (it changes nothing on TCP)."""
