"""A master's options, once: a frozen configuration of its policies.

[`MasterConfig`][aiortu.master.MasterConfig] groups what a [`Master`][aiortu.master.Master] does
about retries ([`RetryPolicy`][aiortu.core.machines.RetryPolicy]), unit health
([`HealthPolicy`][aiortu.master.HealthPolicy]), reconnecting
([`ReconnectPolicy`][aiortu.master.ReconnectPolicy]) and the line's waits
([`TimingPolicy`][aiortu.master.TimingPolicy]). `Master(...)` and `open_master(...)` take one
(`config=`) and the everyday keywords on top of it (`timeout=`, `retries=`, ...: the names of
`MasterConfig.KEYWORDS`), each checked once, here.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar, Final

from aiortu.core.errors import InvalidValue
from aiortu.core.machines import RetryPolicy
from aiortu.core.rtu import TimingMode
from aiortu.master._arguments import (
    check_at_least,
    check_bool,
    check_delays,
    check_function_codes,
    check_retry_on,
    check_seconds,
    check_turnaround,
)
from aiortu.master._stats import HealthPolicy

__all__ = ("MasterConfig", "ReconnectPolicy", "TimingPolicy")


@dataclass(frozen=True, slots=True)
class ReconnectPolicy:
    """Whether and how a master reopens its port (see [`aiortu.master`][aiortu.master]).

    `delay` is `(first, longest)`: seconds before the first attempt to reopen, doubled
    after each failed attempt up to *longest*. With `fail_fast`, requests made while the
    port is down raise [`ConnectionLost`][aiortu.errors.ConnectionLost] at once instead of waiting.
    """

    enabled: bool = True
    delay: tuple[float, float] = (0.1, 5.0)
    fail_fast: bool = False

    def __post_init__(self) -> None:
        check_bool("reconnect", self.enabled)
        object.__setattr__(self, "delay", check_delays("reconnect_delay", self.delay))
        check_bool("reconnect_fail_fast", self.fail_fast)


@dataclass(frozen=True, slots=True)
class TimingPolicy:
    """The waits a master keeps on its line.

    `frame_gap` is the silence kept before each request (`None`: t3.5, or 0 on a stream of
    whole frames such as Modbus TCP's). `turnaround_delay` is the wait after a request
    without reply (a broadcast). `late_reply_guard` is the silence kept after a failed
    attempt before anything goes out. `min_turnaround` is the least time a unit takes from
    the end of a request to the first byte of its reply; `wire_timed` says whether the
    stream's wire times are real (`None`: the stream says). `mode` is the receiver's t1.5
    mode.
    """

    frame_gap: float | None = None
    turnaround_delay: float = 0.1
    late_reply_guard: float = 0.1
    min_turnaround: float = 0.0
    wire_timed: bool | None = None
    mode: TimingMode = TimingMode.TOLERANT

    def __post_init__(self) -> None:
        if self.frame_gap is not None:
            check_seconds("frame_gap", self.frame_gap, zero=True)
        check_seconds("turnaround_delay", self.turnaround_delay, zero=True)
        check_seconds("late_reply_guard", self.late_reply_guard, zero=True)
        check_turnaround(self.min_turnaround)
        if self.wire_timed is not None and not isinstance(self.wire_timed, bool):
            raise InvalidValue(
                "wire_timed", self.wire_timed, "None (from the stream), True or False"
            )
        if not isinstance(self.mode, str) or self.mode not in set(TimingMode):
            raise InvalidValue("timing", self.mode, ", ".join(TimingMode))
        object.__setattr__(self, "mode", TimingMode(self.mode))


def _check_retry(policy: RetryPolicy) -> None:
    check_at_least("retries", policy.retries, 0)
    check_retry_on(policy.retry_on)
    check_function_codes("repeatable", policy.repeatable)


def _check_health(policy: HealthPolicy) -> None:
    check_at_least("offline_after", policy.offline_after, 1)
    check_bool("fail_fast_offline", policy.fail_fast_offline)
    check_seconds("probe_interval", policy.probe_interval, zero=True)


_KEYWORDS: Final[dict[str, tuple[str, str]]] = {
    "retries": ("retry", "retries"),
    "retry_on": ("retry", "retry_on"),
    "repeatable": ("retry", "repeatable"),
    "offline_after": ("health", "offline_after"),
    "fail_fast_offline": ("health", "fail_fast_offline"),
    "probe_interval": ("health", "probe_interval"),
    "reconnect": ("reconnection", "enabled"),
    "reconnect_delay": ("reconnection", "delay"),
    "reconnect_fail_fast": ("reconnection", "fail_fast"),
    "frame_gap": ("timings", "frame_gap"),
    "turnaround_delay": ("timings", "turnaround_delay"),
    "late_reply_guard": ("timings", "late_reply_guard"),
    "min_turnaround": ("timings", "min_turnaround"),
    "wire_timed": ("timings", "wire_timed"),
    "timing": ("timings", "mode"),
}
"""Each everyday keyword: the policy it sets and that policy's field."""

_NONE_IS_DEFAULT: Final = frozenset(("retry_on", "repeatable"))
"""Keywords whose `None` means the policy's default."""


@dataclass(frozen=True, slots=True)
class MasterConfig:
    """How a master runs its line (see the module docstring).

    `timeout` is the response timeout of each attempt, counted from when the request has
    left the wire. `fast_path` false sends every transaction through the master machine
    (for the differential tests and for diagnosis; the results are the same).
    """

    timeout: float = 1.0
    retry: RetryPolicy = field(default_factory=RetryPolicy)
    health: HealthPolicy = field(default_factory=HealthPolicy)
    reconnection: ReconnectPolicy = field(default_factory=ReconnectPolicy)
    timings: TimingPolicy = field(default_factory=TimingPolicy)
    fast_path: bool = True

    KEYWORDS: ClassVar[frozenset[str]] = frozenset(("timeout", "fast_path", *_KEYWORDS))
    """The keywords [`with_options`][aiortu.master.MasterConfig.with_options] takes."""

    def __post_init__(self) -> None:
        check_seconds("timeout", self.timeout)
        object.__setattr__(self, "timeout", float(self.timeout))
        _check_retry(self.retry)
        _check_health(self.health)
        check_bool("fast_path", self.fast_path)

    @classmethod
    def of(cls, **options: Any) -> MasterConfig:
        """The default configuration with the everyday keywords `options` applied:
        `MasterConfig.of(timeout=0.5, retries=0)`."""
        return cls().with_options(**options)

    def with_options(self, **options: Any) -> MasterConfig:
        """This configuration with the everyday keywords `options` applied (each one sets
        one field of one policy; a `retry_on` or `repeatable` of `None` means the default).
        An unknown keyword raises [`InvalidValue`][aiortu.errors.InvalidValue]."""
        if not options:
            return self
        changes: dict[str, dict[str, Any]] = {}
        top: dict[str, Any] = {}
        for name, value in options.items():
            if name in ("timeout", "fast_path"):
                top[name] = value
                continue
            where = _KEYWORDS.get(name)
            if where is None:
                raise InvalidValue(name, value, "an option of MasterConfig", "unknown option")
            if value is None and name in _NONE_IS_DEFAULT:
                changes.setdefault(where[0], {})[where[1]] = getattr(RetryPolicy(), where[1])
            else:
                changes.setdefault(where[0], {})[where[1]] = value
        if "retry" in changes:
            _check_retry_keywords(changes["retry"])
        for policy, values in changes.items():
            top[policy] = dataclasses.replace(getattr(self, policy), **values)
        return dataclasses.replace(self, **top)


def _check_retry_keywords(values: dict[str, Any]) -> None:
    """Check the retry keywords before RetryPolicy converts them (its own errors are plainer)."""
    if "retries" in values:
        check_at_least("retries", values["retries"], 0)
    if "retry_on" in values:
        check_retry_on(values["retry_on"])
    if "repeatable" in values:
        check_function_codes("repeatable", values["repeatable"])
