"""Every stream listener survives running out of file descriptors: 400 connections held to
each in turn, in a process limited to 192 descriptors (`fd_server.py`), under asyncio and
trio; then each answers, with a line or two per listener and no traceback."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from tests.attacks import fd_server
from tests.attacks.listeners import STREAMS, Target, ask, client_context
from tests.attacks.test_listener_attacks import _close_all, _connect_many

pytestmark = pytest.mark.timeout(120)

_KINDS = {"tls": "tls", "unix": "unix"}


def _target(name: str, address: list[object] | str, directory: Path) -> Target:
    scheme = name.split()[1]
    kind = _KINDS.get(scheme, "tcp")
    framing = {"rtu+tcp": "rtu", "ascii+tcp": "ascii", "metrics": "http"}.get(scheme, "mbap")
    where = address if isinstance(address, str) else tuple(address)
    context = client_context(directory) if kind == "tls" else None
    return Target(name, kind, framing, where, None, context)


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_every_listener_survives_running_out_of_file_descriptors(
    backend: str, tmp_path: Path
) -> None:
    process, addresses = fd_server.start(tmp_path, backend)
    try:
        targets = [_target(name, addresses[name], tmp_path) for name in STREAMS]
        for target in targets:
            held = _connect_many(target, 400)
            time.sleep(0.3)
            assert process.poll() is None, "the process died of running out of descriptors"
            _close_all(held)
        for target in targets:
            reply = ask(target)
            assert reply.startswith(target.reply()), f"{target.name}: {reply!r}"
        assert process.poll() is None
    finally:
        process.kill()
        _, err = process.communicate(timeout=10)
    log = err.decode()
    assert "Traceback" not in log
    assert "the listener failed" not in log
    failures = [line for line in log.splitlines() if "cannot accept" in line]
    # At most one line per listener: a warning of a kind once a minute.
    assert 1 <= len(failures) <= len(targets), log
