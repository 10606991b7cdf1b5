"""The same API without async, for scripts, threads and notebooks.

    import aiortu.blocking

    with aiortu.blocking.open_master("/dev/ttyUSB0", baudrate=19200, parity="E") as master:
        print(master.read_holding_registers(17, 0x6B, 3))
        master.slave(17).write_float32(0x10, 21.5)
        master.broadcast.write_register(0x10, 7)

A thin layer over the async API: the master, its unit and broadcast handles, `serve`, the
slave and the pseudo-terminal bus run in an event loop in a thread of its own (a portal), and
each blocking method runs the async one there and waits for it. The methods are made from the
async ones, one line each, so they take the same arguments, say the same in `help()` and raise
the same errors. It works from any thread, from several at once, and where a loop already runs
in the calling thread (Jupyter, IPython, `python -m asyncio`). See `docs/blocking.md`.
"""

from __future__ import annotations

from aiortu._public import publish
from aiortu.blocking._master import (
    BlockingBroadcastHandle,
    BlockingMaster,
    BlockingUnitHandle,
    blocking_master,
)
from aiortu.blocking._portal import Running, running
from aiortu.master import Master
from aiortu.master import open_master as _open_master
from aiortu.slave import Slave
from aiortu.slave import serve as _serve
from aiortu.testing import PtyBus

__all__ = (
    "BlockingBroadcastHandle",
    "BlockingMaster",
    "BlockingUnitHandle",
    "Running",
    "open_master",
    "pty_bus",
    "serve",
    "start_master",
    "start_slave",
)

open_master = blocking_master(
    _open_master,
    """Open `port_or_url` and return a [`BlockingMaster`][aiortu.blocking.BlockingMaster] on it,
    open; close it, or use it in a `with` block. The arguments are
    [`aiortu.open_master`][aiortu.master.open_master]'s; opening errors are raised here.""",
)

start_master = blocking_master(
    Master,
    """Start a [`BlockingMaster`][aiortu.blocking.BlockingMaster] on `stream` (an endpoint of a
    [`VirtualBus`][aiortu.testing.VirtualBus], say); the arguments are
    [`Master`][aiortu.master.Master]'s. The stream is used in the blocking API's loop only.""",
)

serve = running(
    _serve,
    "the server",
    """Serve `units` on `port_or_url` until closed: the
    [`Running`][aiortu.blocking.Running] slave or server that
    [`aiortu.serve`][aiortu.slave.serve] yields (its `value`), with the same arguments.""",
    "Running[Slave | ModbusTcpServer | RtuOverTcpServer]",
)

start_slave = running(
    Slave,
    "the slave",
    """Serve `units` on `stream` until closed (a [`VirtualBus`][aiortu.testing.VirtualBus]
    endpoint, say): the [`Running`][aiortu.blocking.Running] [`Slave`][aiortu.slave.Slave], with
    its arguments.""",
    "Running[Slave]",
)

pty_bus = running(
    PtyBus,
    "the bus",
    """A virtual bus of pseudo-terminals, relaying until closed: the
    [`Running`][aiortu.blocking.Running] [`PtyBus`][aiortu.testing.PtyBus] (its `value` has the
    device `paths`), with its arguments.""",
    "Running[PtyBus]",
)

publish(__name__, __all__, globals())
