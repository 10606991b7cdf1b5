"""The command over Modbus/TCP Security and Modbus ASCII: `serve` and `read` with certificates,
rules and `--framing ascii`, and their errors in one line."""

from __future__ import annotations

import re
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from aiortu.cli import main
from aiortu.testing import PtyBus
from tests.cli.cli_helpers import run_aiortu, start_aiortu, stop
from tests.transport.certificates import Authority

pytestmark = pytest.mark.timeout(60)

DEVICE = "[[slave]]\nunit = 17\n[[slave.holding_registers]]\nstart = 0\nvalues = [5, 6, 7]\n"
READ = ["--unit", "17", "--table", "holding", "--address", "0", "--count", "2"]


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    directory = tmp_path_factory.mktemp("cli-tls")
    ca = Authority(directory)
    server, operator = ca.issue("server", server=True), ca.issue("operator", role="operator")
    expired = ca.issue("expired", role="operator", expired=True)
    config = directory / "device.toml"
    config.write_text(DEVICE, encoding="utf-8")
    rules = directory / "rules.toml"
    rules.write_text("[roles.operator]\nfunction_codes = [3]\n", encoding="utf-8")
    return {
        "config": str(config),
        "rules": str(rules),
        "server": ["--certfile", str(server.certfile), "--keyfile", str(server.keyfile)],
        "client": ["--certfile", str(operator.certfile), "--keyfile", str(operator.keyfile)],
        "expired": ["--certfile", str(expired.certfile), "--keyfile", str(expired.keyfile)],
        "ca": ["--cafile", str(ca.cafile)],
        "directory": directory,
    }


@contextmanager
def serving(*args: str) -> Iterator[tuple[subprocess.Popen[str], str]]:
    """`aiortu serve ARGS` until the block ends; yields it and its first line on stderr."""
    server = start_aiortu("serve", *args)
    try:
        assert server.stderr is not None
        yield server, server.stderr.readline()
    finally:
        stop(server)


def test_serve_and_read_over_tls_with_a_role(files: dict[str, Any]) -> None:
    with serving(
        "tls://127.0.0.1:0", "--config", files["config"], "--rules", files["rules"],
        *files["server"], *files["ca"],
    ) as (_, first):  # fmt: skip
        found = re.search(r"\(port (\d+)\)", first)
        assert found, first
        url = f"tls://127.0.0.1:{found[1]}"
        read = run_aiortu("read", url, *READ, *files["client"], *files["ca"])
        assert read.returncode == 0, read.stderr
        assert read.stdout.split() == ["0", "5", "1", "6"]
        write = run_aiortu(
            "write", url, "--unit", "17", "--table", "holding", "--address", "0", "--values", "9",
            *files["client"], *files["ca"],
        )  # fmt: skip
        assert write.returncode == 4
        assert "ILLEGAL_FUNCTION" in write.stderr
        assert len(write.stderr.strip().splitlines()) == 1


def test_read_with_a_refused_client_certificate_is_one_line(files: dict[str, Any]) -> None:
    with serving(
        "tls://127.0.0.1:0", "--config", files["config"], "--rules", files["rules"],
        *files["server"], *files["ca"],
    ) as (_, first):  # fmt: skip
        found = re.search(r"\(port (\d+)\)", first)
        assert found, first
        read = run_aiortu(
            "read", f"tls://127.0.0.1:{found[1]}", *READ, *files["expired"], *files["ca"]
        )
    assert read.returncode == 1
    assert read.stdout == ""
    assert read.stderr.strip().splitlines() == [
        f"aiortu read: the line failed: the port is gone (tls://127.0.0.1:{found[1]}: the server"
        " refused this client's certificate: it has expired)"
    ]


@pytest.mark.parametrize(
    ("leave_out", "message"),
    [
        ("--keyfile", "aiortu serve: error: keyfile must be given (Modbus/TCP Security needs "
         "the server's certificate and private key)"),
        ("--rules", "aiortu serve: error: rules must be given (a tls:// server grants each "
         "role what its rules allow)"),
    ],
)  # fmt: skip
def test_serve_tls_without_a_key_or_rules_is_one_line(
    files: dict[str, Any], leave_out: str, message: str
) -> None:
    args = ["tls://127.0.0.1:0", "--config", files["config"], "--rules", files["rules"],
            *files["server"], *files["ca"]]  # fmt: skip
    at = args.index(leave_out)
    del args[at : at + 2]
    done = run_aiortu("serve", *args)
    assert done.returncode == 2
    assert done.stderr.strip() == message


def test_a_rule_file_with_an_unknown_key_is_one_line(files: dict[str, Any]) -> None:
    rules = Path(files["directory"]) / "typo.toml"
    rules.write_text("[roles.viewer]\nfunction_codes = [3]\nreadonly = true\n", encoding="utf-8")
    done = run_aiortu(
        "serve", "tls://127.0.0.1:0", "--config", files["config"], "--rules", str(rules),
        *files["server"], *files["ca"],
    )  # fmt: skip
    assert done.returncode == 2
    assert done.stderr.strip() == (
        f"aiortu serve: error: {rules}: roles.viewer.readonly: unknown key "
        "(expected addresses, broadcast, function_codes, read_only, units)"
    )


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["read", "tcp://127.0.0.1:1502", *READ, "--certfile", "operator.crt"],
         "aiortu read: error: --certfile is for a tls:// port (Modbus/TCP Security), not "
         "tcp://127.0.0.1:1502"),
        (["write", "udp://127.0.0.1:1502", "--unit", "1", "--ref", "40001", "--values", "1",
          "--cafile", "ca.pem"],
         "aiortu write: error: --cafile is for a tls:// port (Modbus/TCP Security), not "
         "udp://127.0.0.1:1502"),
        (["read", "tls://127.0.0.1:1502", *READ, "--framing", "ascii"],
         "aiortu read: error: --framing ascii is for a serial device path or rtu+tcp://, not "
         "tls://127.0.0.1:1502, whose frames are Modbus TCP's"),
        (["serve", "tcp://127.0.0.1:0", "--config", "device.toml", "--keyfile", "server.key"],
         "aiortu serve: error: --keyfile is for a tls:// port (Modbus/TCP Security), not "
         "tcp://127.0.0.1:0"),
        (["serve", "/dev/ttyUSB0", "--config", "device.toml", "--rules", "rules.toml"],
         "aiortu serve: error: --rules is for a tls:// port (Modbus/TCP Security), not "
         "/dev/ttyUSB0"),
        (["serve", "udp://127.0.0.1:0", "--config", "device.toml", "--framing", "ascii"],
         "aiortu serve: error: --framing ascii is for a serial device path or rtu+tcp://, not "
         "udp://127.0.0.1:0, whose frames are Modbus TCP's"),
    ],
)  # fmt: skip
def test_an_option_of_another_transport_is_one_line(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    # Refused before any file is read or any port opened: none of these exist.
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert (captured.out, captured.err) == ("", message + "\n")


@pytest.mark.parametrize(
    ("argv", "code", "message"),
    [
        (["read", "TLS://127.0.0.1:1", *READ, "--certfile", "nope.crt", "--keyfile", "nope.key",
          "--cafile", "nope.pem"],
         2, "aiortu read: error: certfile and keyfile must be readable PEM, not nope.crt"),
        (["read", "ascii+tcp://127.0.0.1:1", *READ, "--framing", "ascii"],
         1, "aiortu read: ascii+tcp://127.0.0.1:1: connection refused"),
    ],
)  # fmt: skip
def test_an_option_of_the_ports_own_transport_is_taken(
    argv: list[str], code: int, message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    # A scheme in capitals is the same scheme, and ascii+tcp:// takes --framing ascii (it says
    # what the URL does): the command goes on to the file or the port, which fail as they do.
    assert main(argv) == code
    captured = capsys.readouterr()
    assert captured.err.startswith(message), captured.err


def test_serve_and_read_in_ascii_on_a_pty_bus(files: dict[str, Any]) -> None:
    with PtyBus(ports=2).running_in_thread() as bus:
        first, second = bus.paths
        with serving(second, "--config", files["config"], "--framing", "ascii") as (server, line):
            assert "7 data bits" in line, line  # the pty's 8 bits, said once
            assert server.stderr is not None
            assert "unit 17 on" in server.stderr.readline()
            read = run_aiortu("read", first, *READ, "--framing", "ascii")
    assert read.returncode == 0, read.stderr
    assert read.stdout.split() == ["0", "5", "1", "6"]
