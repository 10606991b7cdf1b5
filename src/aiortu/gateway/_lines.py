"""Several lines in one gateway, each with its own master, routed by unit ranges."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from aiortu.core.codes import UNIT_ADDRESSES
from aiortu.errors import InvalidValue
from aiortu.master import Master

__all__ = ("ALL_UNITS", "GatewayLine", "check_lines", "line_names")

ALL_UNITS = UNIT_ADDRESSES
"""The unit ids a line serves unless told otherwise."""


@dataclass(frozen=True, slots=True)
class GatewayLine:
    """One line of a gateway: its port name (or a running [`Master`][aiortu.master.Master]),
    the unit ids routed to it, a name for statistics (the port name when empty), and the
    [`open_master`][aiortu.master.open_master] arguments of this line alone (`options`, as
    `{"framing": "ascii", "bytesize": 7}` for a Modbus ASCII line), over the gateway's."""

    port: str | Master
    units: range = ALL_UNITS
    name: str = ""
    options: Mapping[str, Any] = field(default_factory=dict)

    @property
    def label(self) -> str:
        """The name statistics and logs use for the line."""
        if self.name:
            return self.name
        return self.port if isinstance(self.port, str) else "line"


def _describe(units: range) -> str:
    return f"{units.start}-{units.stop - 1}"


def check_lines(lines: Sequence[GatewayLine]) -> None:
    """Raise [`InvalidValue`][aiortu.errors.InvalidValue] unless `lines` is at least one line,
    each with a non-empty range of unit ids in 1..247, no two ranges overlapping."""
    if not lines:
        raise InvalidValue("lines", [], "at least one line")
    seen: list[GatewayLine] = []
    for line in lines:
        units = line.units
        if not (
            isinstance(units, range) and units.step == 1 and len(units) and units.start >= 1
        ) or (units.stop > 248):
            raise InvalidValue("units", units, "a range of unit ids within 1..247, step 1")
        for other in seen:
            if units.start < other.units.stop and other.units.start < units.stop:
                raise InvalidValue(
                    "units",
                    _describe(units),
                    "a range no other line has",
                    message=(
                        f"units {_describe(units)} of line {line.label} overlap units "
                        f"{_describe(other.units)} of line {other.label}; give each unit "
                        "to one line"
                    ),
                )
        if line.options and isinstance(line.port, Master):
            raise InvalidValue("options", dict(line.options), "none with a Master given")
        seen.append(line)


def line_names(lines: Sequence[GatewayLine]) -> list[str]:
    """The name of each line for statistics: its label, numbered when several share one
    (masters given without a name)."""
    labels = [line.label for line in lines]
    return [
        f"{label} {index + 1}" if labels.count(label) > 1 else label
        for index, label in enumerate(labels)
    ]
