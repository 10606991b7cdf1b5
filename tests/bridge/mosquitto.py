"""A real mosquitto on a free loopback port, for the bridge's tests and benchmarks, and a
subscriber (paho-mqtt: another MQTT implementation than the bridge's) that records what the
broker delivers."""

from __future__ import annotations

import shutil
import socket
import subprocess
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import paho.mqtt.client as paho

MOSQUITTO = shutil.which("mosquitto") or "/usr/sbin/mosquitto"


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


class Mosquitto:
    """mosquitto on 127.0.0.1:`port`, persistent (a restart keeps the sessions and their
    queued messages); `extra` lines go into its config."""

    def __init__(self, port: int | None = None, extra: str = "") -> None:
        self.port = port or free_port()
        self.dir = Path(tempfile.mkdtemp(prefix="aiortu-mosquitto-"))
        self.config = self.dir / "mosquitto.conf"
        self.config.write_text(
            f"listener {self.port} 127.0.0.1\nallow_anonymous true\npersistence true\n"
            f"persistence_location {self.dir}/\nmax_queued_messages 0\n"
            f"max_inflight_messages 0\nuser root\nlog_dest file {self.dir}/log\n{extra}"
        )
        self.process: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"mqtt://127.0.0.1:{self.port}"

    def start(self) -> None:
        self.process = subprocess.Popen([MOSQUITTO, "-c", str(self.config)])
        self.wait_listening(self.port)

    def wait_listening(self, port: int) -> None:
        """Return once mosquitto accepts connections on `port` (one of its listeners)."""
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
                return
            except OSError:
                time.sleep(0.02)
        raise RuntimeError(f"mosquitto did not start: {(self.dir / 'log').read_text()}")

    def stop(self) -> None:
        if self.process is not None:
            self.process.terminate()
            self.process.wait(10)
            self.process = None

    def close(self) -> None:
        self.stop()
        shutil.rmtree(self.dir, ignore_errors=True)


@dataclass
class Received:
    topic: str
    payload: bytes
    retain: bool
    at: float


@dataclass
class Subscriber:
    """Records every message on `topics` (QoS 1); `persistent` keeps its session on the
    broker across reconnects (clean session off), so nothing sent meanwhile is missed."""

    port: int
    topics: list[str]
    client_id: str = "aiortu-test-subscriber"
    persistent: bool = False
    messages: list[Received] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def __post_init__(self) -> None:
        client = paho.Client(
            paho.CallbackAPIVersion.VERSION2, client_id=self.client_id,
            clean_session=not self.persistent,
        )  # fmt: skip
        client.on_connect = lambda c, *_: c.subscribe([(t, 1) for t in self.topics])
        client.on_message = self._on_message
        client.reconnect_delay_set(0.05, 0.5)
        self.client = client
        client.connect("127.0.0.1", self.port, keepalive=10)
        client.loop_start()
        self.wait_for(client.is_connected, 10)

    def _on_message(self, client: object, userdata: object, message: paho.MQTTMessage) -> None:
        with self.lock:
            self.messages.append(
                Received(message.topic, bytes(message.payload), message.retain, time.monotonic())
            )

    def wait_for(self, condition: object, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if condition():  # type: ignore[operator]
                return
            time.sleep(0.01)
        raise AssertionError(f"not within {timeout} s: {condition}")

    def on(self, topic: str) -> list[bytes]:
        with self.lock:
            return [m.payload for m in self.messages if m.topic == topic]

    def last(self) -> dict[str, bytes]:
        with self.lock:
            return {m.topic: m.payload for m in self.messages}

    def publish(self, topic: str, payload: bytes, qos: int = 1) -> None:
        self.client.publish(topic, payload, qos=qos).wait_for_publish(5)

    def close(self) -> None:
        # Disconnect first: it wakes the network thread, which then ends at once; stopped
        # first, the thread is joined only when its select() times out, a second later.
        self.client.disconnect()
        self.client.loop_stop()
