"""Every listener survives running out of file descriptors: 1,100 connections to a process
limited to 128 (in a subprocess), then each listener still answers, with one log line per
burst of failed accepts and no traceback."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from aiortu.core.mbap import encode_adu
from tests.gateway.helpers import UNIT

pytestmark = pytest.mark.timeout(120)

ROOT = Path(__file__).resolve().parents[2]
FLOOD = 1100


def _flood(port: int, count: int) -> list[socket.socket]:
    """`count` connections to `port`, held open (those the backlog cannot take time out)."""
    held = []
    for _ in range(count):
        sock = socket.socket()
        sock.settimeout(0.5)
        try:
            sock.connect(("127.0.0.1", port))
        except OSError:
            sock.close()
            continue
        held.append(sock)
    return held


def _ask(sock: socket.socket, request: bytes) -> bytes:
    """Send `request` on `sock` and read until the peer closes or 11 bytes (a read's reply)."""
    sock.settimeout(10)
    sock.sendall(request)
    data = b""
    while chunk := sock.recv(65536):
        data += chunk
        if request[:2] == b"\x00\x01" and len(data) >= 11:
            break
    return data


READ = encode_adu(1, UNIT, bytes.fromhex("03 0000 0001"))
REPLY = encode_adu(1, UNIT, bytes.fromhex("03 02 12 34"))


def test_every_listener_survives_running_out_of_file_descriptors(tmp_path: Path) -> None:
    unix_path = str(tmp_path / "gw.sock")
    command = [sys.executable, "-m", "tests.gateway.fd_limit_server", unix_path]
    process = subprocess.Popen(
        command, cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    try:
        assert process.stdout is not None
        ports = json.loads(process.stdout.readline())
        held = _flood(ports["gateway"], FLOOD)
        for name in ("metrics", "serve"):
            held += _flood(ports[name], 50)
        time.sleep(0.5)
        assert process.poll() is None, "the process died of running out of descriptors"
        with socket.socket(socket.AF_UNIX) as unix:
            unix.settimeout(2)
            unix.connect(unix_path)  # waits in the backlog
            time.sleep(0.2)
            assert process.poll() is None
            for sock in held:
                sock.close()
            assert _ask(unix, READ) == REPLY
        for name in ("gateway", "serve"):
            with socket.create_connection(("127.0.0.1", ports[name]), timeout=10) as sock:
                assert _ask(sock, READ) == REPLY
        with socket.create_connection(("127.0.0.1", ports["metrics"]), timeout=10) as sock:
            assert b"aiortu_gateway_client_requests_total" in _ask(
                sock, b"GET /metrics HTTP/1.0\r\n\r\n"
            )
        assert process.poll() is None
    finally:
        process.kill()
        _, err = process.communicate(timeout=10)
    log = err.decode()
    assert "Traceback" not in log
    failures = [line for line in log.splitlines() if "cannot accept" in line]
    # One line per burst and listener: the gateway's, the metrics', the server's, the Unix one's.
    assert 1 <= len(failures) <= 8, log
