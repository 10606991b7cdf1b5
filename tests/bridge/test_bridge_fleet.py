"""A fleet on one machine: eight `aiortu bridge` processes, each on its own virtual line,
into one mosquitto. One subscriber sees every device, its values and availability; a bridge
killed turns its devices unavailable within the keep-alive; a broker restart loses nothing."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from tests.bridge.fleet import BridgeProcess, write_config, write_profile
from tests.bridge.mosquitto import Mosquitto, Subscriber

pytestmark = pytest.mark.timeout(120)

BRIDGES, UNITS, POINTS, KEEPALIVE = 8, 2, 10, 2


def _values(subscriber: Subscriber, node: str) -> int:
    """The value messages of `node` forwarded live (not a retained copy on resubscribing)."""
    with subscriber.lock:
        return sum(
            1 for m in subscriber.messages
            if m.topic.startswith(f"aiortu/{node}-u") and m.topic.rsplit("/", 1)[1][0] == "p"
            and not m.retain
        )  # fmt: skip


def test_a_fleet_of_bridges_into_one_broker(mosquitto: Mosquitto, tmp_path: Path) -> None:
    profile = write_profile(tmp_path / "fleet.toml", POINTS)
    subscriber = Subscriber(mosquitto.port, ["aiortu/#"], "fleet-watcher", persistent=True)
    nodes = [f"b{n}" for n in range(BRIDGES)]
    configs = {
        node: write_config(tmp_path / f"{node}.toml", node=node, units=UNITS, url=mosquitto.url,
                           profile=profile, keepalive=KEEPALIVE)
        for node in nodes
    }  # fmt: skip
    bridges = [BridgeProcess.start(node, config) for node, config in configs.items()]
    try:
        # Every device of every bridge: each value, and available.
        last = subscriber.last
        topics = [f"aiortu/{node}-u{u}/p{p:02}" for node in nodes
                  for u in range(1, UNITS + 1) for p in range(POINTS)]  # fmt: skip
        subscriber.wait_for(lambda: all(t in last() for t in topics), 60)
        assert last()["aiortu/b3-u2/p07"] == b"7.5"
        for node in nodes:
            assert last()[f"aiortu/bridge/{node}/status"] == b"online"
            for u in range(1, UNITS + 1):
                assert last()[f"aiortu/{node}-u{u}/availability"] == b"online"
        # A bridge killed: its status is its last will within 1.5 keep-alives (and a margin).
        killed = time.monotonic()
        bridges[0].kill()
        subscriber.wait_for(lambda: last()["aiortu/bridge/b0/status"] == b"offline", 10)
        assert time.monotonic() - killed <= KEEPALIVE * 1.5 + 2
        # The broker restarted: the others buffer meanwhile and deliver everything after.
        mosquitto.stop()
        time.sleep(2)
        mosquitto.start()
        for node in nodes[1:]:
            subscriber.wait_for(lambda node=node: last()[f"aiortu/bridge/{node}/status"]
                                == b"online", 30)  # fmt: skip
        time.sleep(2)  # the backlogs, and a poll more
        counts = {bridge.node: bridge.stop() for bridge in bridges[1:]}
        time.sleep(0.5)
        for node, count in counts.items():
            assert count["dropped"] == 0
            assert count["waiting"] == 0
            assert count["values"] > 0
            assert _values(subscriber, node) >= count["values"], node
    finally:
        for bridge in bridges:
            if bridge.process.poll() is None:
                bridge.kill()
        subscriber.close()
