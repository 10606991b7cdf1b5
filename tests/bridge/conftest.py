"""The bridge's tests run against a real mosquitto (Debian's package) on a free loopback port."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.bridge.mosquitto import Mosquitto


@pytest.fixture
def mosquitto() -> Iterator[Mosquitto]:
    broker = Mosquitto()
    broker.start()
    try:
        yield broker
    finally:
        broker.close()
