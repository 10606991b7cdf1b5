"""Interop peers that live in a venv of their own (not in the suite's environment): made when
missing, and reused by later runs.

pysunspec2 lives under `AIORTU_PEER_VENVS` (by default the temporary directory). tmodbus 1.1.0
needs Python 3.12 (`AIORTU_PYTHON312`, by default pyenv's 3.12.1, else `python3.12`) and runs
from `AIORTU_TMODBUS_VENV` (/tmp/venv-tmodbus) with cryptography and serialx; minimalmodbus
2.1.1 runs from `AIORTU_MINIMALMODBUS_VENV` (/tmp/venv-minimalmodbus); `.ci/run` makes those two
up front. All come from PyPI. A peer that cannot be had fails the tests that need it, saying
why: these peers are required, never skipped (CI reaches PyPI)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

__all__ = (
    "PYSUNSPEC2",
    "minimalmodbus_python",
    "peer_python",
    "sunspec_models",
    "tmodbus_python",
)

PYSUNSPEC2 = "pysunspec2==1.3.7"
"""The pysunspec2 the interop tests run, pinned so that runs compare like with like."""

PYENV_312 = "/root/.pyenv/versions/3.12.1/bin/python"


def venv_python(venv: Path, base: str | None, packages: list[str], check: str) -> Path:
    """The python of `venv` once `check` (Python code) runs there; made from the interpreter
    `base` with `packages` installed if it does not."""
    python = venv / "bin" / "python"
    probe = [str(python), "-c", check]
    if python.exists() and subprocess.run(probe, capture_output=True, check=False).returncode == 0:
        return python
    if base is None:
        pytest.fail(f"cannot make {venv}: no Python 3.12 (set AIORTU_PYTHON312 to one)")
    for step in (
        [base, "-m", "venv", str(venv)],
        [str(python), "-m", "pip", "install", "-q", *packages],
    ):
        done = subprocess.run(step, capture_output=True, text=True, check=False, timeout=600)
        if done.returncode != 0:
            lines = (done.stderr or done.stdout).strip().splitlines()
            pytest.fail(f"cannot make {venv}: {' '.join(step)}: {lines[-1] if lines else ''}")
    return python


def peer_python(requirement: str, probe: str) -> Path:
    """The python of a venv under `AIORTU_PEER_VENVS` holding `requirement`, made if missing;
    `probe` is a module the venv must import."""
    root = Path(os.environ.get("AIORTU_PEER_VENVS", tempfile.gettempdir()))
    name = "aiortu-peer-" + "".join(c if c.isalnum() else "-" for c in requirement)
    return venv_python(root / name, sys.executable, [requirement], f"import {probe}")


def sunspec_models(python: Path) -> Path:
    """The model definitions (JSON) of the pysunspec2 in the venv of `python`."""
    found = subprocess.run(
        [str(python), "-c", "import sunspec2, os; print(os.path.dirname(sunspec2.__file__))"],
        capture_output=True,
        text=True,
        check=True,
    )
    return Path(found.stdout.strip()) / "models" / "json"


def _python312() -> str | None:
    given = os.environ.get("AIORTU_PYTHON312")
    if given:
        return given
    if os.access(PYENV_312, os.X_OK):
        return PYENV_312
    return shutil.which("python3.12")


def tmodbus_python() -> str:
    """The Python of a venv with tmodbus 1.1.0, cryptography and serialx."""
    return str(
        venv_python(
            Path(os.environ.get("AIORTU_TMODBUS_VENV", "/tmp/venv-tmodbus")),
            _python312(),
            ["tmodbus==1.1.0", "cryptography", "serialx"],
            "import tmodbus, cryptography, serialx; assert tmodbus.__version__ == '1.1.0'",
        )
    )


def minimalmodbus_python() -> str:
    """The Python of a venv with minimalmodbus 2.1.1."""
    return str(
        venv_python(
            Path(os.environ.get("AIORTU_MINIMALMODBUS_VENV", "/tmp/venv-minimalmodbus")),
            sys.executable,
            ["minimalmodbus==2.1.1"],
            "import minimalmodbus; assert minimalmodbus.__version__ == '2.1.1'",
        )
    )
