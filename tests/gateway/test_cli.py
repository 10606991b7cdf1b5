"""`aiortu gateway`: its help, and one line with the right exit code for what is wrong."""

from __future__ import annotations

import socket

import pytest

from aiortu.cli import main


def test_help_has_examples_exit_codes_and_mbpoll(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as raised:
        main(["gateway", "--help"])
    assert raised.value.code == 0
    out = capsys.readouterr().out
    assert "examples:" in out
    assert "exit codes:" in out
    assert "mbpoll -m tcp" in out


@pytest.mark.parametrize(
    ("listen", "message"),
    [
        ("tcp://127.0.0.1:0,prio=1", "only ',priority=N' (an integer) and ',rules=FILE'"),
        ("tcp://127.0.0.1:0,rules=", "only ',priority=N' (an integer) and ',rules=FILE'"),
        ("ftp://127.0.0.1:0", "a server listens on a tcp://, udp://"),
        ("/dev/ttyUSB1", "a server listens on a tcp://, udp://"),
        ("tcp://127.0.0.1:0,rules=/no/such/rules.toml", "/no/such/rules.toml: (file): cannot"),
        ("tls://127.0.0.1:0", "cafile is missing"),
    ],
)
def test_a_bad_listen_url_is_one_line_and_exit_2(
    listen: str, message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["gateway", "/dev/null", "--listen", listen]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert err.count("\n") == 1
    assert "Traceback" not in err


@pytest.mark.parametrize("option", ["--certfile", "--keyfile", "--cafile"])
def test_a_certificate_without_a_tls_listener_is_one_line_and_exit_2(
    option: str, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["gateway", "/dev/null", "--listen", "tcp://127.0.0.1:0", option, "gw.pem"]
    assert main(argv) == 2
    assert capsys.readouterr().err == (
        f"aiortu gateway: error: {option} is for a --listen tls:// (Modbus/TCP Security), and "
        "no --listen is one\n"
    )


def test_a_port_that_cannot_be_opened_is_one_line_and_exit_1(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["gateway", "/dev/no-such-port", "--listen", "tcp://127.0.0.1:0"]) == 1
    err = capsys.readouterr().err
    assert "/dev/no-such-port" in err
    assert err.count("\n") == 1


@pytest.mark.parametrize(
    ("listen", "metrics", "message"),
    [
        ("tcp://127.0.0.1:{busy}", [], "the port is in use"),
        ("tcp://192.0.2.1:1502", [], "not one of this machine's"),
        ("unix:/no/such/folder/gw.sock", [], "the socket's directory does not exist"),
        ("tcp://127.0.0.1:0", ["--metrics", "http://127.0.0.1:{busy}/metrics"], "in use"),
    ],
)
def test_an_address_it_cannot_listen_on_is_one_line_and_exit_1(
    listen: str, metrics: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        args = [listen.format(busy=port), *(item.format(busy=port) for item in metrics)]
        assert main(["gateway", "/dev/null", "--listen", *args]) == 1
    err = capsys.readouterr().err
    assert message in err
    assert err.count("\n") == 1
    assert "Traceback" not in err
