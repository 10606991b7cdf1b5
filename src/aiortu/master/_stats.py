"""What happened between a master and each unit, and when a unit counts as offline.

[`UnitStats`][aiortu.master.UnitStats] holds the counters of one unit and updates them as
transactions end (the engine, `LineEngine`, calls its `count_*` methods);
[`HealthPolicy`][aiortu.master.HealthPolicy] says when a unit counts as offline and what calls to it
do then.

A unit is in one of three states ([`UnitState`][aiortu.master.UnitState]), the same for the master,
the poller ([`aiortu.master.Poller.health`][aiortu.master.Poller.health]) and the `aiortu poll`
command:

- `ONLINE`: its last transaction got a reply;
- `SUSPECT`: its last transactions failed, fewer than `offline_after` of them; it is
  still asked every time, so one CRC error on a noisy line costs one reading, not seconds;
- `OFFLINE`: `offline_after` transactions failed in a row; it is only probed, one request every
  probe interval, from [`UnitStats.last_probe`][aiortu.master.UnitStats.last_probe] on.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from aiortu.core.errors import CRCError
from aiortu.core.machines import Failure, Transaction

__all__ = ("HealthPolicy", "UnitState", "UnitStats")


class UnitState(enum.Enum):
    """Whether a unit answers: see the module docstring."""

    ONLINE = "online"
    SUSPECT = "suspect"
    OFFLINE = "offline"


@dataclass(frozen=True, slots=True)
class HealthPolicy:
    """When a unit counts as offline, and what calls to it do then.

    `offline_after` consecutive failed transactions (timeouts, frame errors) mark a unit
    offline; a success marks it online. With `fail_fast_offline`, calls to an offline
    unit raise [`UnitOffline`][aiortu.errors.UnitOffline] without sending, except one probe every
    `probe_interval` seconds.
    """

    offline_after: int = 3
    fail_fast_offline: bool = False
    probe_interval: float = 5.0

    # A transaction answered only after one of its attempts timed out counts as a failure
    # here (see UnitStats.count_late_success): a unit that answers only late goes offline
    # like one that does not answer, even though each of its late replies is taken.


@dataclass(slots=True)
class UnitStats:
    """What happened between the master and one unit.

    Counters count transactions, except `timeouts`, `crc_errors` and `frame_errors`,
    which count failed attempts (a retried transaction may add several).
    """

    requests: int = 0
    """Transactions sent to the unit (a broadcast counts for unit 0)."""
    successes: int = 0
    """Transactions that got their reply (an exception response counts: the unit answered)."""
    late_successes: int = 0
    """Of those, the ones answered only after an attempt had timed out: the unit is too slow
    for the timeout, and its health counts them as failures."""
    failures: int = 0
    """Transactions that ended without a usable reply (timeouts, frame errors)."""
    timeouts: int = 0
    """Attempts that got no reply in time."""
    crc_errors: int = 0
    """Attempts that ended with a CRC error."""
    frame_errors: int = 0
    """Attempts that ended with any other frame error (framing, malformed reply)."""
    exceptions: int = 0
    """Exception responses received."""
    retries: int = 0
    """Attempts repeated."""
    skipped_frames: int = 0
    """Frames skipped while waiting for this unit (stale, other units, not matching, late)."""
    late_replies: int = 0
    """Of those, the replies to this unit's timed-out requests that came too late."""
    last_latency: float | None = None
    """Seconds from the start of the request to the end of the reply, last success."""
    mean_latency: float | None = None
    """The mean of that latency over every success."""
    consecutive_failures: int = 0
    """Failed transactions since the last success."""
    online: bool = True
    """False after `offline_after` consecutive failures, until a success."""
    last_probe: float = -math.inf
    """When the unit went offline, or a probe was last let through to it since (by the
    master failing fast, or by a poller)."""

    @property
    def state(self) -> UnitState:
        """The unit's state: online, suspect after a failure, offline after enough of them."""
        if not self.online:
            return UnitState.OFFLINE
        return UnitState.SUSPECT if self.consecutive_failures else UnitState.ONLINE

    def next_probe(self, probe_interval: float) -> float | None:
        """When an offline unit may be probed next, on the master's clock; None unless offline."""
        return None if self.online else self.last_probe + probe_interval

    def count_success(self, latency: float, *, exception: bool = False) -> None:
        """A transaction got its reply, `latency` seconds after its request began to go
        out (`exception`: an exception response, which counts: the unit answered)."""
        self.successes += 1
        self.consecutive_failures = 0
        self.online = True
        if exception:
            self.exceptions += 1
        self.last_latency = latency
        mean = self.mean_latency
        self.mean_latency = latency if mean is None else mean + (latency - mean) / self.successes

    def count_failed_attempt(self, transaction: Transaction) -> None:
        """An attempt of `transaction` failed: count it by its cause."""
        error = transaction.frame_error
        if isinstance(error, CRCError):
            self.crc_errors += 1
        elif error is not None:
            self.frame_errors += 1
        elif transaction.failures and transaction.failures[-1] is Failure.TIMEOUT:
            self.timeouts += 1

    def count_late_success(
        self, latency: float, health: HealthPolicy, now: float, *, exception: bool = False
    ) -> None:
        """A transaction got its reply at `now`, but only after an attempt had timed out:
        the caller has its reply, and the unit's health counts a failure (a unit that
        answers only late goes offline like one that never answers)."""
        online, failures = self.online, self.consecutive_failures
        self.count_success(latency, exception=exception)
        self.late_successes += 1
        self.online, self.consecutive_failures = online, failures
        self._failed_in_a_row(health, now)

    def count_failure(self, health: HealthPolicy, now: float) -> None:
        """A transaction ended without a usable reply at `now`: the unit goes offline after
        `health.offline_after` of them in a row."""
        self.failures += 1
        self._failed_in_a_row(health, now)

    def _failed_in_a_row(self, health: HealthPolicy, now: float) -> None:
        self.consecutive_failures += 1
        if self.online and self.consecutive_failures >= health.offline_after:
            self.online = False
            # The first probe comes a whole interval after the unit went offline.
            self.last_probe = now
