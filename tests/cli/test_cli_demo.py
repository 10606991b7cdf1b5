"""``aiortu demo``: as users run it (a subprocess, piped), and the demo API in process."""

from __future__ import annotations

import io
import re
import signal

import pytest

from aiortu.cli import main
from aiortu.cli._demo import PlainRenderer, TableRenderer, header_lines
from aiortu.cli._demo_devices import EnergyMeter, Reading, TemperatureController
from aiortu.cli._demo_system import Demo
from aiortu.core.model import Layout, Table, decode_value
from tests.cli.cli_helpers import run_aiortu, start_aiortu

pytestmark = pytest.mark.timeout(60)


def values_of(lines: list[str], label: str) -> list[float]:
    pattern = re.compile(rf"\b{label} (-?[0-9.]+)")
    return [float(match.group(1)) for line in lines if (match := pattern.search(line))]


def test_demo_runs_for_its_duration_and_shows_the_setpoint_take_effect():
    result = run_aiortu("demo", "--duration", "3", "--seed", "7")
    assert result.returncode == 0, result.stderr
    out = result.stdout
    assert "\x1b[" not in out  # piped: plain lines, no cursor movement
    lines = out.splitlines()
    assert lines[0].startswith("aiortu demo: 3 simulated Modbus RTU devices")
    assert "19200 8E1" in lines[0]
    # Every device's values, with units of measure.
    meter = [line for line in lines if "unit 1 energy meter:" in line]
    assert meter
    assert re.search(
        r"voltage 2[23]\d\.\d V, current \d+\.\d\d A, power \d+ W, energy \d+\.\d{3} kWh \(online",
        meter[-1],
    )
    io_lines = [line for line in lines if "unit 3 digital I/O module:" in line]
    assert io_lines
    assert "pump " in io_lines[-1]
    assert "heartbeat " in io_lines[-1]
    assert any("poll cycle" in line and "ms" in line for line in lines)
    # The setpoint change, and the process value heading for it.
    assert any("master wrote setpoint 45.0 °C to unit 2" in line for line in lines)
    assert any("unit 2 saw its setpoint change 22.0 -> 45.0 °C" in line for line in lines)
    controller = [line for line in lines if "unit 2 temperature controller:" in line]
    setpoints = values_of(controller, "setpoint")
    assert setpoints[0] == 22.0
    assert setpoints[-1] == 45.0
    process = values_of(controller, "process value")
    assert process[0] < 23
    assert process[-1] > process[0] + 5
    assert "pump on" in io_lines[-1]
    assert re.fullmatch(
        r"demo stopped after 3\.\d s: \d+ poll cycles, \d+ transactions, 0 failed", lines[-1]
    )


def test_demo_stops_cleanly_on_sigint():
    process = start_aiortu("demo", "--interval", "0.2")
    assert process.stdout is not None
    try:
        # Wait until it polls: the first block of values.
        for line in process.stdout:
            if "unit 1 energy meter:" in line:
                break
        process.send_signal(signal.SIGINT)
        rest, err = process.communicate(timeout=10)
    finally:
        process.kill()
    assert process.returncode == 0, err
    assert rest.splitlines()[-1].startswith("demo stopped after")
    assert "Traceback" not in err


def test_demo_stops_quietly_when_the_reader_goes_away():
    process = start_aiortu("demo", "--duration", "5", "--interval", "0.1")
    assert process.stdout is not None
    assert process.stdout.readline().startswith("aiortu demo:")
    process.stdout.close()  # as ``| head -1`` does
    assert process.wait(timeout=15) == 0
    assert process.stderr is not None
    assert process.stderr.read() == ""


async def test_demo_in_process():
    async with Demo(baudrate=115200, interval=0.1, first_change=0.3, seed=1) as demo:
        first = await demo.next_snapshot()
        snapshot = first
        while snapshot.elapsed < 1.3:
            snapshot = await demo.next_snapshot()
        meter_store = demo.meter.store.get(Table.INPUT_REGISTERS, EnergyMeter.VOLTAGE, 2)
    assert first.value("controller.setpoint") == pytest.approx(22.0)
    assert snapshot.value("controller.setpoint") == pytest.approx(45.0)
    before = first.value("controller.process_value")
    after = snapshot.value("controller.process_value")
    assert isinstance(before, float)
    assert isinstance(after, float)
    assert after > before + 5
    voltage = snapshot.value("meter.voltage")
    assert isinstance(voltage, float)
    assert 220 < voltage < 240
    # The meter stores CDAB float32: what the poller decoded is what the device holds.
    assert decode_value(meter_store, "float32", Layout.CDAB) == pytest.approx(voltage, abs=3)
    assert snapshot.value("io.pump") is True
    assert snapshot.value("io.fan") is False
    assert all(device.health.online for device in snapshot.devices)
    assert all(device.stats.failures == 0 for device in snapshot.devices)
    assert snapshot.cycle_time.last is not None
    assert snapshot.cycle_time.last < 0.1
    assert snapshot.reads_per_cycle == 6
    texts = [event.text for event in snapshot.events]
    assert any("master wrote setpoint 45.0" in text for text in texts)
    assert any("pump on" in text for text in texts)
    with pytest.raises(KeyError):
        snapshot.value("no.such.point")


async def test_renderers():
    async with Demo(baudrate=115200, interval=0.1, first_change=0.0, seed=2) as demo:
        snapshot = await demo.next_snapshot()
        snapshot = await demo.next_snapshot()
        header = header_lines(demo)
    assert "unit 2  temperature controller" in header[2]
    assert "every 30 s" in header[-1]
    screen = io.StringIO()
    table = TableRenderer(screen, color=False)
    table.draw(snapshot)
    table.draw(snapshot)
    table.close()
    drawn = screen.getvalue()
    assert drawn.startswith("\x1b[?25l")
    rows = len(table.lines(snapshot))
    assert f"\x1b[{rows}F\x1b[J" in drawn
    assert drawn.endswith("\x1b[?25h")
    assert "unit 1  energy meter" in drawn
    assert "outputs        pump on" in drawn
    assert "online" in drawn
    plain = PlainRenderer(io.StringIO(), every=1)
    text = "\n".join(plain.lines(snapshot))
    assert "unit 2 temperature controller: setpoint 45.0 °C" in text
    assert "master wrote setpoint" in text
    # Events are written once.
    assert "master wrote setpoint" not in "\n".join(plain.lines(snapshot))


def test_readings_and_devices_format_values():
    import random

    controller = TemperatureController(random.Random(0))
    setpoint = controller.readings[0]
    assert setpoint.reference == "40001"
    assert setpoint.format(21.54) == "21.5 °C"
    assert setpoint.format(None) == "-"
    assert Reading(setpoint.point, "x").format(True) == "on"
    meter = EnergyMeter(random.Random(0))
    assert [r.reference for r in meter.readings] == ["30001", "30007", "30013", "30343"]
    before = meter.energy
    meter.step(10.0, 10.0)
    assert meter.energy > before


def test_bad_arguments_and_help(capsys):
    for argv in (["demo", "--duration", "0"], ["demo", "--baudrate", "fast"]):
        with pytest.raises(SystemExit) as raised:
            main(argv)
        assert raised.value.code == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 2
    with pytest.raises(SystemExit):
        main(["demo", "--help"])
    out = capsys.readouterr().out
    assert "examples:" in out
    assert "exit codes:" in out
