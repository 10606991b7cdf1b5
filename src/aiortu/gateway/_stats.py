"""Statistics per line, unit and client, and their Prometheus text exposition.

The text format (version 0.0.4) is written here directly: a handful of counters with labels
needs no dependency, and the gateway stays installable without extras.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, fields

__all__ = (
    "DEFAULT_CLIENT_STATISTICS",
    "OTHER_CLIENTS",
    "ClientStatistics",
    "GatewayStatistics",
    "LineStatistics",
    "UnitStatistics",
)


@dataclass(slots=True)
class LineStatistics:
    """What one line of a [`Gateway`][aiortu.gateway.Gateway] carried."""

    transactions: int = 0
    """Requests handed to the line's master (broadcasts included)."""
    coalesced: int = 0
    """Reads answered by an identical read in flight."""
    cache_hits: int = 0
    """Reads answered from the read cache."""
    broadcasts: int = 0
    """Requests to unit 0 sent on the line."""


@dataclass(slots=True)
class UnitStatistics:
    """The requests to one unit of one line, and how they were answered."""

    requests: int = 0
    """Requests to the unit (cache hits and coalesced reads included)."""
    replies: int = 0
    """Replies with data (not an exception)."""
    exceptions: int = 0
    """Exception replies of the device itself (codes other than 0A and 0B)."""
    no_response: int = 0
    """Exception 0B: the unit did not answer, or is offline."""
    no_path: int = 0
    """Exception 0A: the line was down, or no line serves the unit."""


@dataclass(slots=True)
class ClientStatistics:
    """The connections and requests of one client host."""

    connections: int = 0
    """Connections accepted from the host."""
    requests: int = 0
    """Requests received from the host."""
    replies: int = 0
    """Replies sent to it (exceptions included; broadcasts have none)."""
    refused: int = 0
    """Requests of the host the listener's access rules refused (exception 01)."""


DEFAULT_CLIENT_STATISTICS = 256
"""Client hosts counted one by one, unless told otherwise."""

OTHER_CLIENTS = "other"
"""The name under which the hosts beyond the most recent `max_clients` are added up."""


@dataclass(slots=True)
class GatewayStatistics:
    """Counters by line name, by (line name, unit) and by client host.

    At most `max_clients` hosts are counted one by one, those seen most recently; the counts
    of the others are added up under [`OTHER_CLIENTS`][aiortu.gateway.OTHER_CLIENTS], so that
    neither memory nor `/metrics` grows with the number of hosts that ever connected."""

    lines: dict[str, LineStatistics] = field(default_factory=dict)
    units: dict[tuple[str, int], UnitStatistics] = field(default_factory=dict)
    clients: dict[str, ClientStatistics] = field(default_factory=dict)
    max_clients: int = DEFAULT_CLIENT_STATISTICS

    def line(self, name: str) -> LineStatistics:
        """The statistics of line `name`, created empty."""
        return self.lines.setdefault(name, LineStatistics())

    def unit(self, line: str, unit: int) -> UnitStatistics:
        """The statistics of `unit` on line `line`, created empty."""
        key = (line, unit)
        stats = self.units.get(key)
        if stats is None:
            stats = self.units[key] = UnitStatistics()
        return stats

    def client(self, host: str) -> ClientStatistics:
        """The statistics of client `host`, created empty (the least recent host's then added
        to the others' when `max_clients` are counted)."""
        clients = self.clients
        stats = clients.get(host)
        if stats is None:
            stats = clients[host] = ClientStatistics()
            if len(clients) - (OTHER_CLIENTS in clients) > self.max_clients:
                self._fold_oldest()
        elif host != OTHER_CLIENTS and next(reversed(clients)) != host:
            clients[host] = clients.pop(host)  # the most recent last
        return stats

    def _fold_oldest(self) -> None:
        """Add the least recent host's counts to the others' (kept last)."""
        clients = self.clients
        oldest = next(host for host in clients if host != OTHER_CLIENTS)
        folded = clients.pop(oldest)
        other = clients.pop(OTHER_CLIENTS, None) or ClientStatistics()
        for item in fields(ClientStatistics):
            setattr(other, item.name, getattr(other, item.name) + getattr(folded, item.name))
        clients[OTHER_CLIENTS] = other

    def answered(self, line: str, unit: int, reply: bytes) -> None:
        """Count `reply` (a PDU) to a request to `unit` of `line`."""
        stats = self.unit(line, unit)
        if not reply[0] & 0x80:
            stats.replies += 1
        elif reply[1:2] == b"\x0b":
            stats.no_response += 1
        elif reply[1:2] == b"\x0a":
            stats.no_path += 1
        else:
            stats.exceptions += 1

    def summary(self) -> Iterator[str]:
        """One line of text per line, unit and client, for a person to read."""
        for name, line in self.lines.items():
            yield f"line {name}: {_pairs(line)}"
        for (name, number), unit in sorted(self.units.items()):
            yield f"line {name} unit {number}: {_pairs(unit)}"
        for host, client in self.clients.items():
            yield f"client {host}: {_pairs(client)}"

    def prometheus(self) -> str:
        """The counters in the Prometheus text exposition format."""
        out: list[str] = []
        lines = [(_labels(line=name), stats) for name, stats in self.lines.items()]
        _family(out, "line", LineStatistics, lines)
        units = [
            (_labels(line=line, unit=str(unit)), stats)
            for (line, unit), stats in sorted(self.units.items())
        ]
        _family(out, "unit", UnitStatistics, units)
        clients = [(_labels(client=host), stats) for host, stats in self.clients.items()]
        _family(out, "client", ClientStatistics, clients)
        return "".join(out)


def _pairs(stats: object) -> str:
    return " ".join(f"{item.name}={getattr(stats, item.name)}" for item in fields(stats))  # type: ignore[arg-type]


def _labels(**labels: str) -> str:
    return ",".join(f'{key}="{_escape(value)}"' for key, value in labels.items())


def _family(out: list[str], kind: str, cls: type, rows: Sequence[tuple[str, object]]) -> None:
    for item in fields(cls):
        name = f"aiortu_gateway_{kind}_{item.name}_total"
        words = item.name.replace("_", " ")
        out.append(f"# HELP {name} {words} by {kind}\n# TYPE {name} counter\n")
        for labels, stats in rows:
            out.append(f"{name}{{{labels}}} {getattr(stats, item.name)}\n")


def _escape(value: str) -> str:
    return value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")
