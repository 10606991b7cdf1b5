"""The bridge on trio: the broker tests' scenarios, run by trio against the same real mosquitto.

The suite runs in pytest-asyncio's auto mode, which takes every ``async def`` test for
asyncio; so these tests are synchronous and run each scenario, written once in its own
module (where it runs under asyncio), with `anyio.run(..., backend="trio")`: values and Home
Assistant discovery, writes round-tripped and refused, Sparkplug B, unit health, the broker
away (the backlog in order, the bound's count, a broker not there at the start), the
session's redelivery, TLS and a refused login.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Iterator
from functools import partial
from pathlib import Path

import anyio
import pytest

from tests.bridge import test_bridge_broker as broker_tests
from tests.bridge import test_bridge_health as health_tests
from tests.bridge import test_bridge_outage as outage_tests
from tests.bridge import test_bridge_session as session_tests
from tests.bridge import test_bridge_tls as tls_tests
from tests.bridge.mosquitto import Mosquitto, Subscriber

pytestmark = pytest.mark.timeout(120)


def _on_trio(scenario: Callable[[], Awaitable[None]]) -> None:
    anyio.run(scenario, backend="trio")


@pytest.fixture
def subscriber(mosquitto: Mosquitto) -> Iterator[Subscriber]:
    sub = Subscriber(mosquitto.port, ["#"])
    yield sub
    sub.close()


@pytest.mark.parametrize(
    "scenario",
    [
        broker_tests.test_values_and_home_assistant_discovery,
        broker_tests.test_writes_round_trip_and_refusals_go_to_the_error_topic,
        broker_tests.test_sparkplug_births_data_commands_and_rebirth,
    ],
    ids=["values_and_discovery", "writes", "sparkplug"],
)
def test_the_bridge_publishes_and_writes_on_trio(
    scenario: Callable[[Mosquitto, Subscriber], Awaitable[None]],
    mosquitto: Mosquitto,
    subscriber: Subscriber,
) -> None:
    _on_trio(partial(scenario, mosquitto, subscriber))


@pytest.mark.parametrize(
    "scenario",
    [
        outage_tests.test_the_backlog_arrives_in_order_after_a_broker_restart,
        outage_tests.test_what_the_bound_drops_is_counted_and_published,
        health_tests.test_unit_health_is_each_device_s_availability,
        health_tests.test_sparkplug_device_death_and_rebirth,
    ],
    ids=["backlog_in_order", "bound_counted", "unit_health", "sparkplug_death"],
)
def test_the_broker_away_and_unit_health_on_trio(
    scenario: Callable[[Mosquitto], Awaitable[None]], mosquitto: Mosquitto
) -> None:
    _on_trio(partial(scenario, mosquitto))


def test_a_broker_not_there_at_the_start_on_trio() -> None:
    _on_trio(outage_tests.test_an_unreachable_broker_is_waited_for_while_polling)


def test_unacknowledged_messages_go_again_on_trio() -> None:
    _on_trio(session_tests.test_unacknowledged_messages_go_again_first_and_in_order)


@pytest.mark.parametrize(
    "scenario",
    [tls_tests.test_mqtts_with_the_broker_s_ca, outage_tests.test_a_refused_login_stops_the_start],
    ids=["tls", "refused_login"],
)
def test_tls_and_logins_on_trio(
    scenario: Callable[[Path], Awaitable[None]], tmp_path: Path
) -> None:
    _on_trio(partial(scenario, tmp_path))
