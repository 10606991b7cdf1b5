"""The venvs the peers of the transports' interop tests run from, made when missing.

tmodbus 1.1.0 needs Python 3.12 (`AIORTU_PYTHON312`, by default pyenv's 3.12.1, else
`python3.12`) and runs from `AIORTU_TMODBUS_VENV` (/tmp/venv-tmodbus) with cryptography and
serialx; minimalmodbus 2.1.1 runs from `AIORTU_MINIMALMODBUS_VENV` (/tmp/venv-minimalmodbus).
Both come from PyPI; `.ci/run` makes them up front. A peer that cannot be had fails its tests,
saying why: these peers are required, never skipped.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

__all__ = ("minimalmodbus_python", "tmodbus_python")

PYENV_312 = "/root/.pyenv/versions/3.12.1/bin/python"


def _python312() -> str | None:
    given = os.environ.get("AIORTU_PYTHON312")
    if given:
        return given
    if os.access(PYENV_312, os.X_OK):
        return PYENV_312
    return shutil.which("python3.12")


def _venv(venv: Path, base: str | None, packages: list[str], check: str) -> str:
    python = venv / "bin" / "python"
    probe = [str(python), "-c", check]
    if python.exists() and subprocess.run(probe, capture_output=True, check=False).returncode == 0:
        return str(python)
    if base is None:
        pytest.fail(f"cannot make {venv}: no Python 3.12 (set AIORTU_PYTHON312 to one)")
    for step in (
        [base, "-m", "venv", str(venv)],
        [str(python), "-m", "pip", "install", "-q", *packages],
    ):
        done = subprocess.run(step, capture_output=True, text=True, check=False, timeout=600)
        if done.returncode != 0:
            pytest.fail(f"cannot make {venv}: {' '.join(step)}: {done.stderr[-500:]}")
    return str(python)


def tmodbus_python() -> str:
    """The Python of a venv with tmodbus 1.1.0, cryptography and serialx."""
    return _venv(
        Path(os.environ.get("AIORTU_TMODBUS_VENV", "/tmp/venv-tmodbus")),
        _python312(),
        ["tmodbus==1.1.0", "cryptography", "serialx"],
        "import tmodbus, cryptography, serialx; assert tmodbus.__version__ == '1.1.0'",
    )


def minimalmodbus_python() -> str:
    """The Python of a venv with minimalmodbus 2.1.1."""
    return _venv(
        Path(os.environ.get("AIORTU_MINIMALMODBUS_VENV", "/tmp/venv-minimalmodbus")),
        sys.executable,
        ["minimalmodbus==2.1.1"],
        "import minimalmodbus; assert minimalmodbus.__version__ == '2.1.1'",
    )
