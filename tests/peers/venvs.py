"""Interop peers that live in a venv of their own (not in the suite's environment): made once,
kept under the temporary directory, and reused by later runs.

A peer that cannot be installed fails the tests that need it, with pip's last line: these
peers are required, not optional (CI reaches PyPI)."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

PYSUNSPEC2 = "pysunspec2==1.3.7"
"""The pysunspec2 the interop tests run, pinned so that runs compare like with like."""


def peer_python(requirement: str, probe: str) -> Path:
    """The python of a venv holding `requirement`, made if missing; `probe` is a module the
    venv must import."""
    root = Path(os.environ.get("AIORTU_PEER_VENVS", tempfile.gettempdir()))
    name = "aiortu-peer-" + "".join(c if c.isalnum() else "-" for c in requirement)
    python = root / name / "bin" / "python"
    check = [str(python), "-c", f"import {probe}"]
    if python.exists() and subprocess.run(check, capture_output=True, check=False).returncode == 0:
        return python
    subprocess.run([sys.executable, "-m", "venv", str(root / name)], check=True)
    install = subprocess.run(
        [str(python), "-m", "pip", "install", "-q", requirement],
        capture_output=True,
        text=True,
        check=False,
        timeout=600,
    )
    lines = (install.stderr or install.stdout).strip().splitlines()
    assert install.returncode == 0, f"pip install {requirement}: {lines[-1] if lines else ''}"
    return python


def sunspec_models(python: Path) -> Path:
    """The model definitions (JSON) of the pysunspec2 in the venv of `python`."""
    found = subprocess.run(
        [str(python), "-c", "import sunspec2, os; print(os.path.dirname(sunspec2.__file__))"],
        capture_output=True,
        text=True,
        check=True,
    )
    return Path(found.stdout.strip()) / "models" / "json"
