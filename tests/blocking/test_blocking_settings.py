"""The blocking API where users run it: a plain script, IPython with its loop running in the
calling thread, and the asyncio REPL (where the async master's own exit gives a clear error)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

SETUP = """\
import asyncio, aiortu, aiortu.blocking
from aiortu.slave import MemoryStore
from aiortu.testing import VirtualBus
bus = VirtualBus(2)
store = MemoryStore(holding_registers={0: 10})
slave = aiortu.blocking.start_slave(bus[1], {1: store}, frame_gap=0)
m = aiortu.blocking.start_master(bus[0], frame_gap=0)
m.write_registers(1, 2, [7, 8])
"""


def _run(argv: list[str], stdin: str = "") -> str:
    done = subprocess.run(
        argv, input=stdin, capture_output=True, text=True, timeout=60, check=False
    )
    assert done.returncode == 0, done.stderr
    return done.stdout + done.stderr


def test_a_plain_script_that_forgets_to_close_still_exits() -> None:
    script = SETUP + "print('read', m.read_holding_registers(1, 1, 3))\n"
    assert "read [0, 7, 8]" in _run([sys.executable, "-c", script])


def test_ipython_with_its_loop_running_in_the_calling_thread() -> None:
    cells = SETUP + textwrap.dedent("""\
        await asyncio.sleep(0); print("running", asyncio.get_running_loop().is_running(), "read", m.read_holding_registers(1, 2, 2))
        m.close(); slave.close(); print("closed", m.closed)
        """)  # noqa: E501
    argv = [sys.executable, "-m", "IPython", "--simple-prompt", "--quick", "--no-banner"]
    output = _run([*argv, "--colors=NoColor"], cells + "exit\n")
    assert "running True read [7, 8]" in output
    assert "closed True" in output


def test_the_asyncio_repl() -> None:
    statements = SETUP + textwrap.dedent("""\
        print("running", asyncio.get_running_loop().is_running(), "read", m.read_holding_registers(1, 2, 2))
        m.close(); slave.close(); print("closed", m.closed)
        master = aiortu.Master(VirtualBus(2)[0], frame_gap=0)
        await master.__aenter__()
        try:
            await master.__aexit__(None, None, None)
        except RuntimeError as error:
            print("error:", error)

        print("still open", master.connected)
        """)  # noqa: E501
    output = _run([sys.executable, "-m", "asyncio"], statements)
    assert "running True read [7, 8]" in output
    assert "closed True" in output
    assert "error: a master must be left in the task that entered it" in output
    assert "still open True" in output
