"""`aiortu profile`, `serve --profile` and `poll --profile`: a shipped profile served, read,
written and polled by name in subprocesses, over Modbus TCP on loopback."""

from __future__ import annotations

import json
import socket
import time
from pathlib import Path

import pytest

from aiortu.cli import main
from aiortu.core.model import parse_profile, schema_reference
from tests.cli.cli_helpers import run_aiortu, start_aiortu, stop
from tests.peers.venvs import PYSUNSPEC2, peer_python, sunspec_models

ROOT = Path(__file__).parents[2]


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def wait_listening(port: int) -> None:
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline:
        with socket.socket() as client:
            if client.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.05)
    raise AssertionError(f"nothing listens on {port}")


def test_check_summarises_a_good_profile_and_names_the_error_of_a_bad_one(
    tmp_path: Path,
) -> None:
    good = run_aiortu("profile", "check", "eastron-sdm630")
    assert good.returncode == 0, good.stderr
    assert "Eastron SDM630, 87 points" in good.stdout
    assert "normal: 75 points in 4 reads every 1 s" in good.stdout
    bad = tmp_path / "bad.toml"
    bad.write_text(
        '[device]\nmanufacturer = "A"\nmodel = "B"\n\n[[point]]\nname = "x"\n'
        'address = 0\ntype = "float"\n'
    )
    result = run_aiortu("profile", "check", str(bad))
    assert result.returncode == 2
    assert result.stderr.strip() == (
        f"aiortu profile: error: {bad}:6: point x.type: unknown type 'float' "
        "(known: bool, u16, i16, u32, i32, u64, i64, f32, f64, string, bitfield, enum)"
    )


def test_the_reference_page_is_what_the_schema_writes() -> None:
    page = (ROOT / "docs/profile-reference.md").read_text(encoding="utf-8")
    assert page == schema_reference(), "run: aiortu profile reference > docs/profile-reference.md"


def test_a_profile_served_read_written_and_polled_by_name() -> None:
    port = free_port()
    url = f"tcp://127.0.0.1:{port}"
    server = start_aiortu("serve", url, "--profile", "eastron-sdm630", "--unit", "3")
    try:
        wait_listening(port)
        common = ("--unit", "3", "--profile", "eastron-sdm630")
        read = run_aiortu(
            "profile", "read", url, *common, "--point", "l1_voltage", "--point", "frequency"
        )
        assert read.returncode == 0, read.stderr
        assert read.stdout.splitlines() == ["l1_voltage 230.0 V", "frequency 50.0 Hz"]
        write = run_aiortu("profile", "write", url, *common, "demand_period", "15")
        assert write.returncode == 0, write.stderr
        after = run_aiortu("profile", "read", url, *common, "--point", "demand_period", "--json")
        assert json.loads(after.stdout) == {"unit": 3, "values": {"demand_period": 15.0}}
        refused = run_aiortu("profile", "write", url, *common, "demand_period", "99")
        assert refused.returncode == 2
        assert refused.stderr.strip().endswith(
            "eastron-sdm630.toml: point demand_period: value 99 is outside the limits 0..60"
        )
        read_only = run_aiortu("profile", "write", url, *common, "l1_voltage", "1")
        assert "point l1_voltage: is read-only" in read_only.stderr
        polled = run_aiortu(
            "poll", url, "--unit", "3", "--profile", "eastron-sdm630", "--cycles", "1", "--json"
        )
        assert polled.returncode == 0, polled.stderr
        lines = [json.loads(line) for line in polled.stdout.splitlines()]
        assert len(lines) == 87
        assert {
            "unit": 3,
            "name": "l1_voltage",
            "value": 230.0,
            "unit_of_measurement": "V",
        } in lines
    finally:
        stop(server)


@pytest.mark.parametrize(
    "args",
    [
        ("serve", "tcp://127.0.0.1:1", "--profile", "eastron-sdm630", "--config", "x.toml"),
        ("serve", "tcp://127.0.0.1:1"),
    ],
)
def test_serve_wants_one_description(args: tuple[str, ...]) -> None:
    result = run_aiortu(*args)
    assert result.returncode == 2
    assert "give --config or --profile" in result.stderr


def test_a_sunspec_device_served_and_walked_into_a_profile(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    python = peer_python(PYSUNSPEC2, "sunspec2")
    monkeypatch.setenv("AIORTU_SUNSPEC_MODELS", str(sunspec_models(python)))
    made = run_aiortu(
        "profile", "sunspec", "1", "103", "--value", "m103.W=1500", "--value", "m1.Mn=ACME"
    )
    assert made.returncode == 0, made.stderr
    simulated = tmp_path / "sim.toml"
    simulated.write_text(made.stdout)
    port = free_port()
    url = f"tcp://127.0.0.1:{port}"
    server = start_aiortu("serve", url, "--profile", str(simulated), "--unit", "2")
    try:
        wait_listening(port)
        walked = run_aiortu("profile", "walk", url, "--unit", "2")
        assert walked.returncode == 0, walked.stderr
        profile = parse_profile(walked.stdout, "walked.toml")
        assert profile.device.manufacturer == "ACME"
        assert profile.point("m103.W").unit == "W"
        (tmp_path / "walked.toml").write_text(walked.stdout)
        read = run_aiortu(
            "profile",
            "read",
            url,
            "--unit",
            "2",
            "--profile",
            str(tmp_path / "walked.toml"),
            "--point",
            "m103.W",
        )
        assert read.stdout.strip() == "m103.W 1500.0 W"
    finally:
        stop(server)


def test_units_are_matched_against_profiles() -> None:
    port = free_port()
    url = f"tcp://127.0.0.1:{port}"
    pump = str(ROOT / "examples/profiles/heat-pump.toml")
    server = start_aiortu("serve", url, "--profile", pump, "--unit", "4")
    try:
        wait_listening(port)
        result = run_aiortu(
            "profile", "match", url, "--unit", "4", "--profile", pump, "--profile", "eastron-sdm630"
        )
        assert result.returncode == 0, result.stderr
        assert result.stdout.splitlines() == [
            f"unit 4: ACME HP-7 ({pump}) by device identification, probes"
        ]
    finally:
        stop(server)


def test_home_assistant_and_evcc_files_are_imported(tmp_path: Path) -> None:
    ha = run_aiortu(
        "profile",
        "import",
        "home-assistant",
        str(ROOT / "examples/imports/home-assistant-modbus.yaml"),
        "--out-dir",
        str(tmp_path),
    )
    assert ha.returncode == 0, ha.stderr
    written = sorted(p.name for p in tmp_path.iterdir())
    assert written == ["heating-unit1.toml", "heating-unit2.toml", "heating-unit3.toml"]
    checked = run_aiortu("profile", "check", *(str(p) for p in sorted(tmp_path.iterdir())))
    assert checked.returncode == 0, checked.stderr
    assert "heating-unit1.toml: Home Assistant heating unit 1, 12 points" in checked.stdout
    evcc = run_aiortu(
        "profile",
        "import",
        "evcc",
        str(ROOT / "examples/imports/evcc-meter.yaml"),
        "--param",
        "usage=pv",
    )
    assert evcc.returncode == 0, evcc.stderr
    assert parse_profile(evcc.stdout, "evcc.toml").point("power").scale == -1.0
    assert evcc.stderr.strip() == "aiortu profile: skipped soc: no Modbus register (source 'const')"
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        "modbus:\n  - name: hub\n    sensors:\n      - name: X\n        address: 1\n"
        "        data_type: float16\n"
    )
    refused = run_aiortu("profile", "import", "home-assistant", str(bad))
    assert refused.returncode == 2
    assert refused.stderr.strip() == (
        "aiortu profile: error: bad.yaml: hub.sensors[0] (X).data_type: 'float16' has no "
        "profile type (known: int8, int16, int32, int64, uint8, uint16, uint32, uint64, "
        "float32, float64, string)"
    )


def test_scan_says_which_profile_each_unit_found_matches(tmp_path: Path) -> None:
    bus = start_aiortu(
        "virtual-bus",
        "--ports",
        "2",
        "--parity",
        "N",
        "--stopbits",
        "2",
        "--link-dir",
        str(tmp_path),
    )
    served = None
    pump = str(ROOT / "examples/profiles/heat-pump.toml")
    try:
        assert bus.stdout is not None
        ports = [bus.stdout.readline().strip() for _ in range(2)]
        served = start_aiortu(
            "serve", ports[1], "--profile", pump, "--unit", "4", "--parity", "N", "--stopbits", "2"
        )
        assert served.stderr is not None
        assert "unit 4 on" in served.stderr.readline()
        result = run_aiortu(
            "scan",
            ports[0],
            "--baudrates",
            "19200",
            "--parities",
            "N",
            "--units",
            "1-5",
            "--timeout",
            "0.1",
            "--profile",
            pump,
            "--profile",
            "eastron-sdm630",
        )
        assert result.returncode == 0, result.stderr
        assert result.stdout.splitlines()[-2:] == [
            "found 1 unit (4) at 19200 8N2",
            f"unit 4: ACME HP-7 ({pump}, by device identification, probes)",
        ]
    finally:
        if served is not None:
            stop(served)
        bus.terminate()
        bus.wait(timeout=10)


@pytest.mark.parametrize(
    "argv",
    [
        ["serve", "/nonexistent/ttyX", "--profile", "eastron-sdm63"],
        ["poll", "/nonexistent/ttyX", "--unit", "1", "--profile", "eastron-sdm63"],
        ["profile", "read", "/nonexistent/ttyX", "--unit", "1", "--profile", "eastron-sdm63"],
        ["scan", "/nonexistent/ttyX", "--units", "1", "--profile", "eastron-sdm63"],
    ],
)
def test_an_unknown_profile_name_is_one_line_naming_the_shipped_ones(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    # Said before the port is opened (scan: before it scans): the port does not exist.
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert (captured.out, captured.err) == (
        "",
        f"aiortu {argv[0]}: error: eastron-sdm63: (file): no such file, nor a shipped profile "
        "(one of: eastron-sdm630, sunspec-inverter)\n",
    )


@pytest.mark.parametrize(
    ("port", "code", "message"),
    [
        ("/nonexistent/ttyX", 1, "/nonexistent/ttyX: no such serial device"),
        ("tls://127.0.0.1:0", 2, "error: cafile must be given"),
    ],
)
def test_serve_profile_failing_to_open_is_one_line(
    port: str, code: int, message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    # The profile's device is served in a task group (for --move); a failure leaves it as the
    # command's one line and exit code, not as an exception group's traceback.
    assert main(["serve", port, "--profile", "eastron-sdm630", "--move", "5"]) == code
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith(f"aiortu serve: {message}"), captured.err
