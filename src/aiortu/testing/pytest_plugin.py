"""The aiortu pytest plugin: fixtures for virtual serial lines, loaded when aiortu is installed.

Registered through the `pytest11` entry point, so any suite gets these fixtures:

- `virtual_pair`: the two endpoints of an unpaced in-memory line, `(a, b)`.
- `virtual_bus`: a factory, `virtual_bus(ports=3, settings=..., faults=...)`, that
  returns a ready [`VirtualBus`][aiortu.testing.VirtualBus], usable at once or with
  `async with`.
- `pty_bus`: a factory, `pty_bus(ports=2, settings=..., faults=...)`, that returns a
  running [`PtyBus`][aiortu.testing.PtyBus] (its relay runs in a background thread), whose
  `paths` any program can open.

Everything the fixtures make is closed at the end of the test.

The fixtures are synchronous on purpose. An in-memory bus needs no background task, and
the pty relay runs in an event loop of its own, so nothing is tied to the test's event
loop or task: the fixtures work in pytest-asyncio suites in auto and strict mode, under
anyio's pytest plugin (asyncio or trio), in plain synchronous tests, and in runs where
pytest-asyncio is not installed.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any, Protocol

import pytest

from aiortu.testing._pty_bus import PtyBus
from aiortu.testing._virtual_bus import VirtualBus, VirtualEndpoint
from aiortu.testing._virtual_bus import virtual_pair as make_virtual_pair

__all__ = ("PtyBusFactory", "VirtualBusFactory", "pty_bus", "virtual_bus", "virtual_pair")


class VirtualBusFactory(Protocol):
    """The type of the `virtual_bus` fixture: takes [`VirtualBus`][aiortu.testing.VirtualBus]'s
    arguments."""

    def __call__(self, ports: int = 2, **options: Any) -> VirtualBus: ...


class PtyBusFactory(Protocol):
    """The type of the `pty_bus` fixture: takes [`PtyBus`][aiortu.testing.PtyBus]'s arguments."""

    def __call__(self, ports: int = 2, **options: Any) -> PtyBus: ...


@pytest.fixture
def virtual_pair() -> Iterator[tuple[VirtualEndpoint, VirtualEndpoint]]:
    """The two endpoints of an unpaced in-memory line; closed after the test."""
    first, second = make_virtual_pair()
    yield first, second
    first.bus.close()


@pytest.fixture
def virtual_bus() -> Iterator[VirtualBusFactory]:
    """A factory of in-memory buses; every bus it made is closed after the test."""
    buses: list[VirtualBus] = []

    def factory(ports: int = 2, **options: Any) -> VirtualBus:
        bus = VirtualBus(ports, **options)
        buses.append(bus)
        return bus

    yield factory
    for bus in buses:
        bus.close()


@pytest.fixture
def pty_bus() -> Iterator[PtyBusFactory]:
    """A factory of running pty buses; every bus it started is stopped after the test."""
    with contextlib.ExitStack() as stack:

        def factory(ports: int = 2, **options: Any) -> PtyBus:
            return stack.enter_context(PtyBus(ports, **options).running_in_thread())

        yield factory
