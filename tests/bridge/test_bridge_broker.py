"""The bridge against a real mosquitto: values, Home Assistant discovery, availability,
writes round-tripped and refused, Sparkplug B checked by pysparkplug."""

from __future__ import annotations

import json
from collections.abc import Iterator

import anyio
import pytest
from pysparkplug import DataType as SpDataType
from pysparkplug import Topic

from aiortu.bridge import Bridge, DataType, Metric, SparkplugPayload, encode_payload
from tests.bridge.helpers import FAST_POLL, config, fast_heat_pump
from tests.bridge.mosquitto import Mosquitto, Subscriber

pytestmark = pytest.mark.timeout(60)


@pytest.fixture
def subscriber(mosquitto: Mosquitto) -> Iterator[Subscriber]:
    sub = Subscriber(mosquitto.port, ["#"])
    yield sub
    sub.close()


async def until(condition: object, within: float = 10) -> None:
    """Poll `condition` (a bounded wait: the test fails after `within` seconds)."""
    with anyio.fail_after(within):
        while not condition():  # type: ignore[operator]  # noqa: ASYNC110
            await anyio.sleep(0.02)


async def test_values_and_home_assistant_discovery(
    mosquitto: Mosquitto, subscriber: Subscriber
) -> None:
    async with Bridge(config(mosquitto.url, profile=fast_heat_pump())) as bridge:
        await until(lambda: "aiortu/hp-2/setpoint" in subscriber.last())
        last = subscriber.last()
        assert last["aiortu/bridge/test/status"] == b"online"
        assert last["aiortu/hp-1/power"] == b"1800.0"
        assert last["aiortu/hp-1/flow_temperature"] == b"35.5"
        assert last["aiortu/hp-1/mode"] == b"heat"
        assert last["aiortu/hp-1/serial"] == b"HP7-0042"
        assert last["aiortu/hp-1/availability"] == b"online"
        assert last["aiortu/hp-1/health"] == b"online"
        energy = json.loads(last["homeassistant/sensor/test/hp_1_energy/config"])
        assert energy["state_topic"] == "aiortu/hp-1/energy"
        assert energy["unit_of_measurement"] == "kWh"
        assert energy["device_class"] == "energy"
        assert energy["state_class"] == "total_increasing"
        assert energy["device"]["identifiers"] == ["aiortu_hp-1"]
        assert energy["device"]["manufacturer"] == "ACME"
        assert energy["device"]["model"] == "HP-7"
        assert energy["availability_mode"] == "all"
        assert [a["topic"] for a in energy["availability"]] == [
            "aiortu/bridge/test/status", "aiortu/hp-1/availability"]  # fmt: skip
        setpoint = json.loads(last["homeassistant/number/test/hp_1_setpoint/config"])
        assert setpoint["command_topic"] == "aiortu/hp-1/setpoint/set"
        assert (setpoint["min"], setpoint["max"]) == (20, 55)
        mode = json.loads(last["homeassistant/select/test/hp_1_mode/config"])
        assert mode["options"] == ["off", "heat", "cool", "auto"]
        assert "homeassistant/switch/test/hp_1_pump/config" in last
        # On change: a value published once, until it changes (over four polls).
        await anyio.sleep(4 * FAST_POLL)
        assert subscriber.on("aiortu/hp-1/power") == [b"1800.0"]
        bridge.simulated["hp-1"].set_value("power", 2500.0)
        await until(lambda: subscriber.on("aiortu/hp-1/power")[-1:] == [b"2500.0"], 5)
    await until(lambda: subscriber.on("aiortu/bridge/test/status")[-1:] == [b"offline"], 5)


async def test_every_poll_points_are_published_every_poll(
    mosquitto: Mosquitto, subscriber: Subscriber
) -> None:
    every = config(mosquitto.url, units=(1,), device='every_poll = ["power"]',
                   profile=fast_heat_pump())  # fmt: skip
    async with Bridge(every):
        # Three polls published (the temperature goes before the power in each).
        await until(lambda: len(subscriber.on("aiortu/hp-1/power")) >= 3)
    assert len(subscriber.on("aiortu/hp-1/flow_temperature")) == 1


async def test_writes_round_trip_and_refusals_go_to_the_error_topic(
    mosquitto: Mosquitto, subscriber: Subscriber
) -> None:
    async with Bridge(config(mosquitto.url)) as bridge:
        await until(lambda: "aiortu/hp-1/setpoint" in subscriber.last())
        subscriber.publish("aiortu/hp-1/setpoint/set", b"50.5")
        await until(lambda: subscriber.on("aiortu/hp-1/setpoint")[-1:] == [b"50.5"])
        assert bridge.simulated["hp-1"].value("setpoint") == 50.5
        subscriber.publish("aiortu/hp-1/mode/set", b"cool")
        subscriber.publish("aiortu/hp-1/pump/set", b"ON")
        await until(lambda: subscriber.on("aiortu/hp-1/pump")[-1:] == [b"true"])
        assert subscriber.on("aiortu/hp-1/mode")[-1] == b"cool"
        refused = {
            b"99": "outside the limits 20..55",
            b"warm": "is not a number",
            b"\xff": "not UTF-8",
        }
        for payload in refused:
            subscriber.publish("aiortu/hp-1/setpoint/set", payload)
        subscriber.publish("aiortu/hp-1/power/set", b"1")
        subscriber.publish("aiortu/hp-1/nothing/set", b"1")
        subscriber.publish("aiortu/hp-2/mode/set", b"turbo")
        await until(lambda: len(subscriber.on("aiortu/hp-1/error")) == 5)
        errors = [json.loads(e) for e in subscriber.on("aiortu/hp-1/error")]
        for error, reason in zip(errors, refused.values(), strict=False):
            assert error["point"] == "setpoint"
            assert reason in error["error"]
        assert "read-only" in errors[3]["error"]
        assert "no point named 'nothing'" in errors[4]["error"]
        await until(lambda: len(subscriber.on("aiortu/hp-2/error")) == 1)
        assert "turbo" in json.loads(subscriber.on("aiortu/hp-2/error")[0])["error"]
        assert bridge.simulated["hp-1"].value("setpoint") == 50.5
        assert bridge.stats.write_errors == 6
        # The bridge goes on.
        bridge.simulated["hp-1"].set_value("power", 10.0)
        await until(lambda: subscriber.on("aiortu/hp-1/power")[-1:] == [b"10.0"])


async def test_a_refused_write_is_logged_once_as_not_done(
    mosquitto: Mosquitto, subscriber: Subscriber, caplog: pytest.LogCaptureFixture
) -> None:
    async with Bridge(config(mosquitto.url, units=(1,))):
        await until(lambda: "aiortu/hp-1/setpoint" in subscriber.last())
        subscriber.publish("aiortu/hp-1/setpoint/set", b"99")
        await until(lambda: len(subscriber.on("aiortu/hp-1/error")) == 1)
    logged = [r.getMessage() for r in caplog.records if r.name == "aiortu.bridge._bridge"]
    assert (
        "write of hp-1.setpoint not done: refused: point setpoint: value 99 is outside the "
        "limits 20..55"
    ) in logged


def _sparkplug(subscriber: Subscriber) -> list[tuple[str, object]]:
    """Every Sparkplug message so far, decoded by pysparkplug."""
    with subscriber.lock:
        found = [m for m in subscriber.messages if m.topic.startswith("spBv1.0/")]
    decoded = []
    for m in found:
        topic = Topic.from_str(m.topic)
        decoded.append((m.topic, topic.message_type.payload.decode(m.payload)))
    return decoded


def _of(messages: list[tuple[str, object]], topic: str) -> list[object]:
    return [payload for t, payload in messages if t == topic]


async def test_sparkplug_births_data_commands_and_rebirth(
    mosquitto: Mosquitto, subscriber: Subscriber
) -> None:
    node = "spBv1.0/aiortu/{}/test"
    sparkplug = config(mosquitto.url, layout="sparkplug")
    async with Bridge(sparkplug) as bridge:
        await until(lambda: len(_of(_sparkplug(subscriber), node.format("DBIRTH") + "/hp-2")) == 1)
        messages = _sparkplug(subscriber)
        (nbirth,) = _of(messages, node.format("NBIRTH"))
        assert nbirth.seq == 0
        metrics = {m.name: m for m in nbirth.metrics}
        assert metrics["bdSeq"].value == 0
        assert metrics["Node Control/Rebirth"].value is False
        (dbirth,) = _of(messages, node.format("DBIRTH") + "/hp-1")
        values = {m.name: (m.datatype, m.value) for m in dbirth.metrics}
        assert values["power"] == (SpDataType.FLOAT, 1800.0)
        assert values["flow_temperature"] == (SpDataType.DOUBLE, 35.5)
        assert values["model_code"] == (SpDataType.UINT16, 7)
        assert values["mode"] == (SpDataType.STRING, "heat")
        assert values["pump"] == (SpDataType.BOOLEAN, False)
        seqs = [p.seq for t, p in messages if not any(k in t for k in ("/NDEATH/", "CMD/"))]
        assert seqs == list(range(len(seqs)))
        # DDATA on change.
        bridge.simulated["hp-1"].set_value("power", 900.0)
        ddata = node.format("DDATA") + "/hp-1"
        await until(lambda: _of(_sparkplug(subscriber), ddata))
        (data,) = _of(_sparkplug(subscriber), ddata)
        assert [(m.name, m.value) for m in data.metrics] == [("power", 900.0)]
        # DCMD writes, NCMD asks for the births again.
        write = SparkplugPayload(0, (Metric("setpoint", DataType.DOUBLE, 50.0),))
        subscriber.publish(node.format("DCMD") + "/hp-1", encode_payload(write), qos=0)
        await until(lambda: bridge.simulated["hp-1"].value("setpoint") == 50.0)
        rebirth = SparkplugPayload(0, (Metric("Node Control/Rebirth", DataType.BOOLEAN, True),))
        subscriber.publish(node.format("NCMD"), encode_payload(rebirth), qos=0)
        await until(lambda: len(_of(_sparkplug(subscriber), node.format("NBIRTH"))) == 2)
        await until(lambda: len(_of(_sparkplug(subscriber), node.format("DBIRTH") + "/hp-1")) == 2)
        reborn = _of(_sparkplug(subscriber), node.format("DBIRTH") + "/hp-1")[-1]
        assert {m.name: m.value for m in reborn.metrics}["setpoint"] == 50.0
        # Sequence numbers go on, 0 again at each NBIRTH.
        messages = _sparkplug(subscriber)
        seqs = [p.seq for t, p in messages if not any(k in t for k in ("/NDEATH/", "CMD/"))]
        restart = seqs.index(0, 1)
        assert seqs[:restart] == list(range(restart))
        assert seqs[restart:] == list(range(len(seqs) - restart))
    # The connection gone, the broker publishes the node's last will: NDEATH, the same bdSeq.
    await until(lambda: _of(_sparkplug(subscriber), node.format("NDEATH")), 10)
    (ndeath,) = _of(_sparkplug(subscriber), node.format("NDEATH"))
    assert (ndeath.bd_seq_metric.name, ndeath.bd_seq_metric.value) == ("bdSeq", 0)
