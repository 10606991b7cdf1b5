"""The example scripts run on their own and print what they promise."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).parent.parent / "examples"


@pytest.mark.parametrize(
    ("script", "expected"),
    [
        ("poll_several_devices.py", "cycle 2 unit 3 voltage3   231.250"),
        ("poll_several_devices.py", "unit 4: offline"),
        ("typed_values.py", "float32 CDAB at 2: 0000 41AC -> 21.5"),
        ("typed_values.py", "40108 = holding register 107 = 0x022B"),
        ("slave_with_handler.py", "temperatures: [21.5, 21.6, 21.7, 21.8]"),
        ("slave_with_handler.py", "observer: holding_registers 2: [0, 0] -> [7, 8]"),
        ("proxy_store.py", "the far device now holds: [100, 200, 300, 401]"),
    ],
)
def test_an_example_runs_and_prints(script: str, expected: str) -> None:
    result = subprocess.run(
        [sys.executable, str(EXAMPLES / script)],
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert expected in result.stdout.splitlines() or any(
        line.startswith(expected) for line in result.stdout.splitlines()
    ), result.stdout
