"""`mqtts://`: the bridge checks the broker's certificate against the CA it is given; a CA
that is not the broker's fails the connection, a CA file that cannot be read stops it with
one sentence."""

from __future__ import annotations

import subprocess
from dataclasses import replace
from pathlib import Path

import pytest

from aiortu.bridge import Bridge, BridgeConfig, BrokerError
from tests.bridge.helpers import config
from tests.bridge.mosquitto import Mosquitto, Subscriber, free_port
from tests.bridge.test_bridge_broker import until

pytestmark = pytest.mark.timeout(60)


def _certificates(folder: Path, name: str) -> tuple[Path, Path, Path]:
    """A CA, and a server certificate for 127.0.0.1 it signed."""
    ca_key, ca, key, csr, cert = (folder / f"{name}{s}" for s in
                                  ("-ca.key", "-ca.crt", ".key", ".csr", ".crt"))  # fmt: skip
    run = lambda *args: subprocess.run(["openssl", *args], check=True, capture_output=True)  # noqa: E731
    run("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", ca_key, "-out", ca,
        "-days", "2", "-subj", f"/CN={name} test CA")  # fmt: skip
    run("req", "-newkey", "rsa:2048", "-nodes", "-keyout", key, "-out", csr, "-subj",
        "/CN=127.0.0.1")  # fmt: skip
    extensions = folder / "san.cnf"
    extensions.write_text("subjectAltName = IP:127.0.0.1\n")
    run("x509", "-req", "-in", csr, "-CA", ca, "-CAkey", ca_key, "-CAcreateserial", "-out", cert,
        "-days", "2", "-extfile", extensions)  # fmt: skip
    return ca, cert, key


async def test_mqtts_with_the_broker_s_ca(tmp_path: Path) -> None:
    ca, cert, key = _certificates(tmp_path, "broker")
    other_ca, _, _ = _certificates(tmp_path, "other")
    plain_port = free_port()
    broker = Mosquitto(extra=f"cafile {ca}\ncertfile {cert}\nkeyfile {key}\n"
                             f"listener {plain_port} 127.0.0.1\n")  # fmt: skip

    def secured(ca_file: Path) -> BridgeConfig:
        plain = config(broker.url.replace("mqtt://", "mqtts://"), units=(1,))
        return replace(plain, broker=replace(plain.broker, ca_file=str(ca_file)))

    broker.start()
    subscriber: Subscriber | None = None
    try:
        broker.wait_listening(plain_port)  # the listeners open one after the other
        subscriber = watcher = Subscriber(plain_port, ["aiortu/#"])
        async with Bridge(secured(ca)) as bridge:
            assert bridge.session.connected
            await until(lambda: watcher.on("aiortu/hp-1/power") == [b"1800.0"])
        # A broker whose certificate does not check stops the start, in one sentence.
        with pytest.raises(BrokerError, match=r"TLS failed: .*certificate"):
            async with Bridge(secured(other_ca)):
                pass
        with pytest.raises(BrokerError, match="the broker's certificates cannot be loaded"):
            async with Bridge(secured(tmp_path / "none")):
                pass
    finally:
        if subscriber is not None:
            subscriber.close()
        broker.close()  # also when the subscriber could not connect
