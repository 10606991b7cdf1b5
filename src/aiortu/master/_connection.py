"""Keeping a master's line up: serve the line on a link, reopen the port when it dies.

A USB serial adapter can vanish under a running program. `LineConnection` runs the
master's `LineEngine` on a [`Link`][aiortu.line.Link]; when
the link fails, the request in flight and those queued fail with
[`ConnectionLost`][aiortu.errors.ConnectionLost], and then:

- without an `opener` (a [`Master`][aiortu.master.Master] given a bare stream) or with
  reconnecting off, the master stays failed: every later request raises ConnectionLost;
- with one (`open_master` passes one that opens the same port with the same settings),
  the port is reopened with exponential backoff, from `delay[0]` doubling up to
  `delay[1]` seconds, until it comes back. Meanwhile requests wait for it within their
  own timeout and raise ConnectionLost if it is not back by then, or at once with
  `fail_fast`. Once it is back, requests go out as before; unit health and statistics
  are kept across the reconnect.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable

import anyio
import anyio.abc

from aiortu._log import get_logger
from aiortu.errors import ConnectionLost, ModbusError
from aiortu.line import Link
from aiortu.master._config import ReconnectPolicy
from aiortu.master._engine import LineEngine

__all__ = ("LineConnection", "StreamOpener", "can_reconnect")

_log = get_logger(__name__)

StreamOpener = Callable[[], Awaitable[anyio.abc.ByteStream]]
"""An async function that opens the line's byte stream again (the same port and settings)."""


class LineConnection:
    """Runs `engine` on `link`, and on links over streams from `opener` after it fails
    (when `policy` lets it: see `can_reconnect`).

    `make_link` wraps a freshly opened stream in a link with the master's settings.
    Counters: `disconnects`, `reconnects`, `failed_attempts`.
    """

    def __init__(
        self,
        engine: LineEngine,
        link: Link,
        make_link: Callable[[anyio.abc.ByteStream], Link],
        opener: StreamOpener | None,
        policy: ReconnectPolicy,
    ) -> None:
        self.engine = engine
        self.link = link
        """The current link (a new one after each reconnect)."""
        self.policy = policy
        self._make_link = make_link
        self._opener = opener
        self.disconnects = 0
        """Times the line failed under the master."""
        self.reconnects = 0
        """Times the port was reopened."""
        self.failed_attempts = 0
        """Attempts to reopen the port that failed."""
        self.last_error: ConnectionLost | None = None
        """Why the line last failed."""

    @property
    def can_reconnect(self) -> bool:
        """Whether the port is reopened after it fails (an opener, and reconnecting on)."""
        return can_reconnect(self._opener, self.policy)

    @property
    def connected(self) -> bool:
        """Whether the line is up now."""
        return self.engine.connected

    async def wait_connected(self) -> None:
        """Wait until the line is up (at once if it is), or the master is closed."""
        await self.engine.wait_connected()

    async def run(self) -> None:
        """Serve the line until cancelled, or until it fails and cannot be reopened."""
        link = self.link
        try:
            while True:
                async with link:
                    error = await self.engine.line_task.serve(link)
                self.disconnects += 1
                self.last_error = error
                if not self.can_reconnect:
                    self.engine.close(error)
                    return
                _log.warning("%s; reopening it", error)  # says "the line failed: why"
                link = self.link = self._make_link(await self._reopen())
                self.reconnects += 1
                _log.info("the line is back after %d failed attempts", self.failed_attempts)
        finally:
            self.engine.close(ConnectionLost("the master is closed"))

    async def _reopen(self) -> anyio.abc.ByteStream:
        assert self._opener is not None
        delay, longest = self.policy.delay
        while True:
            await anyio.sleep(delay)
            try:
                return await self._opener()
            except (OSError, ModbusError) as error:
                self.failed_attempts += 1
                _log.debug("reopening failed (%s); next attempt in %.3g s", error, delay)
                delay = min(2 * delay, longest)


def can_reconnect(opener: StreamOpener | None, policy: ReconnectPolicy) -> bool:
    """Whether a master with `opener` reopens its port after it fails under `policy`."""
    return opener is not None and policy.enabled
