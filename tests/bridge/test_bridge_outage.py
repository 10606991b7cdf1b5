"""Nothing lost while the broker is away: the bridge polls on, buffers within its bound,
reconnects and delivers the backlog in order; what the bound dropped is counted and
published. And the bad inputs: an unreachable broker, a bad URL, a refused login, unknown
profiles and points."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import anyio
import pytest

from aiortu.bridge import Bridge, BrokerError, parse_config
from aiortu.errors import ConfigError
from tests.bridge.helpers import HEAT_PUMP, config, fast_heat_pump
from tests.bridge.mosquitto import Mosquitto, Subscriber, free_port
from tests.bridge.test_bridge_broker import until

pytestmark = pytest.mark.timeout(90)
RECONNECT_DELAY = (0.1, 0.4)
"""The back-off between connection attempts, capped low: the tests wait for the broker to come
back, not for the back-off to reach its default cap of 5 s."""


def _distinct(payloads: list[bytes]) -> list[bytes]:
    """`payloads` without repeats in a row: QoS 1 is at least once, and a subscriber that
    subscribes again gets the retained value again."""
    return [p for n, p in enumerate(payloads) if n == 0 or payloads[n - 1] != p]


async def _count_through_an_outage(broker: Mosquitto, bridge: Bridge, values: int) -> None:
    """Stop the broker, change the power `values` times, each once the bridge has read the
    one before (and so queued its message), start it again."""
    broker.stop()
    await until(lambda: not bridge.session.connected, 10)
    store = bridge.simulated["hp-1"]
    (device,) = (d for d in bridge.devices if d.name == "hp-1")
    for n in range(values):
        store.set_value("power", float(n))
        # Not the outbox's length: the messages put back unacknowledged when the broker
        # went are in it too, and a value set before the last was read would be lost.
        await until(lambda n=n: device.values.get("power") == float(n), 5)
    broker.start()


async def test_the_backlog_arrives_in_order_after_a_broker_restart(mosquitto: Mosquitto) -> None:
    # The subscriber's session persists on the broker: it misses nothing after the restart.
    subscriber = Subscriber(mosquitto.port, ["aiortu/hp-1/power"], "keeper", persistent=True)
    try:
        # Polled every 0.25 s: the values of the outage are a quarter of a second apart.
        async with Bridge(config(mosquitto.url, units=(1,), profile=fast_heat_pump())) as bridge:
            bridge.session.reconnect_delay = RECONNECT_DELAY
            await until(lambda: subscriber.on("aiortu/hp-1/power") == [b"1800.0"])
            await _count_through_an_outage(mosquitto, bridge, 5)
            expected = [b"1800.0"] + [f"{n}.0".encode() for n in range(5)]
            await until(lambda: _distinct(subscriber.on("aiortu/hp-1/power")) == expected, 20)
            assert bridge.outbox.dropped == 0
            assert bridge.session.connections >= 2
    finally:
        subscriber.close()


async def test_what_the_bound_drops_is_counted_and_published(mosquitto: Mosquitto) -> None:
    subscriber = Subscriber(mosquitto.port, ["aiortu/#"], "keeper", persistent=True)
    # Every point every poll, polled every 0.25 s: about 24 messages a second for a bound
    # of 20.
    bounded = config(mosquitto.url, units=(1,), device='publish = "every"',
                     extra="[buffer]\nmax_messages = 20\n",
                     profile=fast_heat_pump())  # fmt: skip
    try:
        async with Bridge(bounded) as bridge:
            bridge.session.reconnect_delay = RECONNECT_DELAY
            await until(lambda: subscriber.on("aiortu/hp-1/power")[:1] == [b"1800.0"])
            mosquitto.stop()
            await until(lambda: bridge.outbox.dropped > 0, 15)
            readings = bridge.stats.readings
            bridge.simulated["hp-1"].set_value("power", 4.0)
            # Two polls later the new value has been read, on a loaded machine too.
            await until(lambda: bridge.stats.readings >= readings + 2, 15)
            assert len(bridge.outbox) <= 20
            mosquitto.start()
            await until(lambda: bridge.session.connected and not bridge.outbox, 20)
            dropped = str(bridge.outbox.dropped).encode()
            await until(lambda: subscriber.on("aiortu/bridge/test/dropped")[-1:] == [dropped], 10)
            # The new value, read while the broker was away, arrives (the backlog may still be
            # on its way to the subscriber when the count does; which messages the bound
            # keeps, oldest dropped first, is tested on the outbox itself).
            await until(lambda: b"4.0" in subscriber.on("aiortu/hp-1/power"), 10)
    finally:
        subscriber.close()


async def test_an_unreachable_broker_is_waited_for_while_polling() -> None:
    port = free_port()
    broker = Mosquitto(port)
    async with Bridge(config(broker.url, units=(1,))) as bridge:
        await until(lambda: bridge.stats.readings > 0, 5)
        assert not bridge.session.connected
        assert len(bridge.outbox) > 0
        broker.start()
        try:
            subscriber = Subscriber(port, ["aiortu/hp-1/power"])
            await until(lambda: subscriber.on("aiortu/hp-1/power") == [b"1800.0"], 20)
            subscriber.close()
        finally:
            broker.close()


async def test_a_refused_login_stops_the_start(tmp_path: Path) -> None:
    passwords = tmp_path / "passwords"
    passwords.write_text("")
    await anyio.run_process(["mosquitto_passwd", "-b", str(passwords), "user", "right"])
    broker = Mosquitto(extra=f"password_file {passwords}\n")
    broker.config.write_text(
        broker.config.read_text().replace("allow_anonymous true", "allow_anonymous false")
    )
    broker.start()
    try:
        wrong = config(broker.url.replace("mqtt://", "mqtt://user:wrong@"), units=(1,))
        with pytest.raises(BrokerError, match=r"refused the user name or password|not authorised"):
            async with Bridge(wrong):
                pass
        right = config(broker.url.replace("mqtt://", "mqtt://user:right@"), units=(1,))
        async with Bridge(right) as bridge:
            assert bridge.session.connected
    finally:
        broker.close()


@pytest.mark.parametrize(
    ("url", "problem"),
    [
        ("http://127.0.0.1:1883", "the scheme must be mqtt:// or mqtts://"),
        ("mqtt://127.0.0.1:99999", "the port must be a number 1..65535"),
        ("mqtt://:1883", "names no host"),
        ("mqtt://host:1883/topic", "has more than a host and port"),
    ],
)
def test_bad_broker_urls_are_one_sentence(url: str, problem: str) -> None:
    with pytest.raises(BrokerError) as caught:
        config(url)
    assert str(caught.value) == f"test.toml: broker URL {url!r}: {problem}"


_LINE = '[broker]\nurl = "{url}"\n[[line]]\nport = "virtual"\n[[line.device]]\n'
_KNOWN = "every_poll, name, points, profile, publish, unit"
_SHIPPED = "eastron-sdm630, sunspec-inverter"


@pytest.mark.parametrize(
    ("device", "message"),
    [
        (
            'profile = "nope"',
            f"line[0].device[0].profile: unknown profile 'nope' (a file, or one of: {_SHIPPED})",
        ),
        (
            f'profile = "{HEAT_PUMP}"\npoints = ["power", "watts"]',
            "line[0].device[0].points[1]: profile 'HP-7' has no point named 'watts'",
        ),
        (
            f'profile = "{HEAT_PUMP}"\nevery_poll = ["volts"]',
            "line[0].device[0].every_poll[0]: profile 'HP-7' has no point named 'volts'",
        ),
        (
            f'profile = "{HEAT_PUMP}"\npublish = "sometimes"',
            'line[0].device[0].publish: must be "change" or "every", not \'sometimes\'',
        ),
        (
            f'profile = "{HEAT_PUMP}"\npoints = []',
            "line[0].device[0].points: must be a list of point names (none: omit it)",
        ),
        (
            f'profile = "{HEAT_PUMP}"\ncolour = 1',
            f"line[0].device[0].colour: unknown key (known: {_KNOWN})",
        ),
    ],
)
def test_config_mistakes_are_one_line(device: str, message: str) -> None:
    text = _LINE.format(url="mqtt://127.0.0.1:1883") + f"unit = 1\n{device}\n"
    with pytest.raises(ConfigError) as caught:
        parse_config(text, "bridge.toml")
    assert str(caught.value) == f"bridge.toml: {message}"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('[topics]\nretain = "yes"\n', "topics.retain: must be true or false, not 'yes'"),
        (
            '[topics]\nlayout = "xml"\n',
            "topics.layout: must be one of home-assistant, plain, sparkplug",
        ),
        ("[topics]\nqos = 2\n", "topics.qos: must be 0 or 1, not 2"),
        ("[buffer]\nmax_messages = 0\n", "buffer.max_messages: must be an integer >= 1, not 0"),
    ],
)
def test_topic_and_buffer_mistakes_are_one_line(text: str, message: str) -> None:
    line = _LINE.format(url="mqtt://127.0.0.1:1883") + f'unit = 1\nprofile = "{HEAT_PUMP}"\n'
    with pytest.raises(ConfigError) as caught:
        parse_config(text + line, "bridge.toml")
    assert str(caught.value) == f"bridge.toml: {message}"


def test_the_command_says_what_is_wrong_in_one_line(tmp_path: Path) -> None:
    bad_url = tmp_path / "url.toml"
    bad_url.write_text(_LINE.format(url="mqtt:/x") + f'unit = 1\nprofile = "{HEAT_PUMP}"\n')
    bad_profile = tmp_path / "profile.toml"
    bad_profile.write_text(_LINE.format(url="mqtt://127.0.0.1:1") + 'unit = 1\nprofile = "nope"\n')
    for path, code, text in (
        (bad_url, 1, "names no host"),
        (bad_profile, 2, "unknown profile 'nope'"),
    ):
        done = subprocess.run([sys.executable, "-m", "aiortu", "bridge", "--config", str(path)],
                              capture_output=True, text=True, timeout=60, check=False)  # fmt: skip
        assert done.returncode == code
        assert done.stderr.count("\n") == 1
        assert text in done.stderr


_LONG = 65_536 - len("aiortu/hp-1/")
"""A point name that makes its plain topic, `aiortu/hp-1/NAME`, one byte too long."""


def _profile_with_a_point(tmp_path: Path, name: str) -> Path:
    """A profile of one writable register named `name`."""
    path = tmp_path / "long.toml"
    path.write_text(f'[device]\nmanufacturer = "M"\nmodel = "L"\n[[point]]\nname = "{name}"\n'
                    'address = 0\ntype = "u16"\naccess = "rw"\n')  # fmt: skip
    return path


def _with_profile(profile: Path, topics: str = "") -> str:
    return (topics + _LINE.format(url="mqtt://127.0.0.1:1")
            + f'name = "hp-1"\nunit = 1\nprofile = "{profile}"\n')  # fmt: skip


@pytest.mark.parametrize(
    ("layout", "name", "size"),
    [
        ("plain", "p" * (_LONG - 4), 65_536),  # its command topic, NAME/set
        ("plain", "p" * (_LONG - 5), None),  # 65,535 bytes: fits
        ("home-assistant", "p" * (_LONG - 4), 65_536),
        ("home-assistant", "p" * (_LONG - 5), 65_559),  # its discovery topic, longer
        ("sparkplug", "p" * _LONG, None),  # a metric is no topic
    ],
)
def test_a_topic_over_mqtts_limit_is_refused_when_loaded(
    tmp_path: Path, layout: str, name: str, size: int | None
) -> None:
    text = _with_profile(_profile_with_a_point(tmp_path, name), f'[topics]\nlayout = "{layout}"\n')
    if size is None:
        parse_config(text, "bridge.toml")
        return
    with pytest.raises(BrokerError) as caught:
        parse_config(text, "bridge.toml")
    message = str(caught.value)
    assert message.startswith("bridge.toml: the topic of device 'hp-1', point 'pppp")
    assert f" is {size:,} bytes, more than the 65,535 an MQTT topic holds" in message
    assert len(message) < 300
    assert "\n" not in message


@pytest.mark.parametrize("key", ["client_id", "username", "password"])
def test_a_broker_string_over_mqtts_limit_is_refused_when_loaded(key: str) -> None:
    text = _LINE.format(url="mqtt://127.0.0.1:1") + f'unit = 1\nprofile = "{HEAT_PUMP}"\n'
    text = text.replace("[[line]]", f'{key} = "{"x" * 65_536}"\n[[line]]')
    with pytest.raises(BrokerError) as caught:
        parse_config(text, "bridge.toml")
    name = key.replace("_", " ")
    assert str(caught.value) == (
        f"bridge.toml: broker {name}: 65,536 bytes, more than the 65,535 MQTT allows"
    )
    parse_config(text.replace("x" * 65_536, "x" * 65_535), "bridge.toml")


def test_the_bridges_own_topics_are_checked_in_bytes() -> None:
    # 32,760 characters of two bytes each: the status topic (the last will's) is too long.
    prefix = "é" * 32_760
    line = _LINE.format(url="mqtt://127.0.0.1:1") + f'unit = 1\nprofile = "{HEAT_PUMP}"\n'
    text = f'[topics]\nlayout = "plain"\nprefix = "{prefix}"\n' + line
    with pytest.raises(BrokerError) as caught:
        parse_config(text, "test")
    assert str(caught.value).startswith("test: the topic of the bridge is 65,541 bytes, more")


def test_the_command_refuses_a_topic_too_long_in_one_line(tmp_path: Path) -> None:
    profile = _profile_with_a_point(tmp_path, "p" * _LONG)
    path = tmp_path / "bridge.toml"
    path.write_text(_with_profile(profile))
    done = subprocess.run([sys.executable, "-m", "aiortu", "bridge", "--config", str(path)],
                          capture_output=True, text=True, timeout=60, check=False)  # fmt: skip
    assert done.returncode == 1
    assert done.stderr.count("\n") == 1
    assert "device 'hp-1', point 'pppp" in done.stderr
    assert "is 65,540 bytes" in done.stderr
    assert "Traceback" not in done.stderr


def test_the_command_counts_its_devices_and_lines_in_words(tmp_path: Path) -> None:
    # No broker listens: the bridge starts all the same, polls, and keeps the messages.
    site = tmp_path / "site.toml"
    url = f"mqtt://127.0.0.1:{free_port()}"
    site.write_text(_LINE.format(url=url) + f'unit = 1\nprofile = "{HEAT_PUMP}"\n')
    command = [sys.executable, "-m", "aiortu", "bridge", "--config", str(site)]
    process = subprocess.Popen(command, stderr=subprocess.PIPE, text=True)
    try:
        assert process.stderr is not None
        lines = [process.stderr.readline()]  # first, that the broker cannot be reached
        while lines[-1] and "Ctrl-C to stop" not in lines[-1]:
            lines.append(process.stderr.readline())
        started = lines[-1]
    finally:
        process.send_signal(signal.SIGTERM)
        _, err = process.communicate(timeout=30)
    assert started.startswith(f"aiortu bridge: 1 device on 1 line to {url} "), started + err
    assert process.returncode == 0, err
