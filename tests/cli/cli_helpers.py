"""Running the ``aiortu`` command in a subprocess, for the CLI tests."""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys
from collections.abc import Iterator


def aiortu_command(*args: str) -> list[str]:
    """The command line that runs ``aiortu ARGS`` with this interpreter."""
    return [sys.executable, "-m", "aiortu", *args]


def run_aiortu(*args: str, timeout: float = 30) -> subprocess.CompletedProcess[str]:
    """Run ``aiortu ARGS`` to its end; its output and exit status, whatever they are."""
    return subprocess.run(
        aiortu_command(*args), capture_output=True, text=True, timeout=timeout, check=False
    )


def start_aiortu(*args: str) -> subprocess.Popen[str]:
    """Start ``aiortu ARGS`` with its standard output and error piped as text."""
    return subprocess.Popen(
        aiortu_command(*args), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


def stop(process: subprocess.Popen[str], how: signal.Signals = signal.SIGTERM) -> tuple[str, str]:
    """Send *how* to *process*; its standard output and error once it exited with 0."""
    process.send_signal(how)
    out, err = process.communicate(timeout=10)
    assert process.returncode == 0, err
    return out, err


@contextlib.contextmanager
def serving_tcp(config: str | os.PathLike[str], *options: str) -> Iterator[str]:
    """``aiortu serve tcp://127.0.0.1:0 --config CONFIG OPTIONS`` running; its URL."""
    process = start_aiortu("serve", "tcp://127.0.0.1:0", "--config", os.fspath(config), *options)
    try:
        assert process.stderr is not None
        line = process.stderr.readline()
        found = re.search(r"\(port (\d+)\)", line)
        assert found is not None, line + process.stderr.read()
        yield f"tcp://127.0.0.1:{found.group(1)}"
    finally:
        stop(process)
