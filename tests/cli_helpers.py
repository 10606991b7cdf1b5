"""Running the ``aiortu`` command in a subprocess, for the CLI tests."""

from __future__ import annotations

import signal
import subprocess
import sys


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
