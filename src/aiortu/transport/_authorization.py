"""Authorization by role: which requests a Modbus/TCP Security client may make.

A server maps each role (read from the client's certificate) to an
[`AccessRule`][aiortu.transport.AccessRule]: the function codes allowed, optionally the units and
the address ranges, and a read-only switch. Anything a rule does not allow is refused, and so is
every request of a role that has no rule (default deny). A refused request is answered with
exception 01 (illegal function), as the spec says, before it reaches a store or a line.

Rules come from Python or from a TOML file ([`load_rules`][aiortu.transport.load_rules]):

```toml
default_role = "viewer"        # optional: the role of a certificate without one

[roles.viewer]
function_codes = [1, 2, 3, 4]
read_only = true

[roles.operator]
function_codes = [1, 2, 3, 4, 5, 6, 15, 16]
units = [1, 17]                # optional: every unit when left out
addresses = [[0, 99], [200, 299]]   # optional, inclusive: every address when left out
broadcast = false              # optional: unit 0 (a broadcast on a serial line)
```

A listener without client certificates (the gateway's `tcp://`, `rtu+tcp://` and `unix:`
listeners) gives no client a role: its clients get the rule of `default_role`.

`broadcast` decides unit 0 alone when it is given (true: allowed, false: refused, whatever
`units` says); left out, unit 0 is allowed when `units` is left out or lists 0.

An unknown key, a value of the wrong type or out of range is a one-line
[`ConfigError`][aiortu.errors.ConfigError]: `FILE: KEY: PROBLEM`.
"""

from __future__ import annotations

import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

from aiortu.core.model import TomlReader
from aiortu.errors import ConfigError

__all__ = ("WRITE_FUNCTION_CODES", "AccessRule", "RoleRules", "load_rules")

WRITE_FUNCTION_CODES: Final = frozenset({0x05, 0x06, 0x08, 0x0F, 0x10, 0x15, 0x16, 0x17})
"""The codes a read-only rule refuses: every write, and diagnostics (whose sub-functions
restart the device, clear its counters or silence it)."""

# Where the data-table address (and quantity) of a request sit in its PDU, by function code:
# (offset of the address, offset of the quantity or None for one element).
_ADDRESSED: Final[dict[int, tuple[tuple[int, int | None], ...]]] = {
    0x01: ((1, 3),),
    0x02: ((1, 3),),
    0x03: ((1, 3),),
    0x04: ((1, 3),),
    0x05: ((1, None),),
    0x06: ((1, None),),
    0x0F: ((1, 3),),
    0x10: ((1, 3),),
    0x16: ((1, None),),
    0x17: ((1, 3), (5, 7)),
    0x18: ((1, None),),
}


def _spans(pdu: bytes) -> list[tuple[int, int]] | None:
    """The (first, last) addresses `pdu` touches; [] for a code without a table address; None
    when the PDU is too short to say."""
    layout = _ADDRESSED.get(pdu[0])
    if layout is None:
        return []
    spans = []
    for address_at, count_at in layout:
        needed = (count_at if count_at is not None else address_at) + 2
        if len(pdu) < needed:
            return None
        first = int.from_bytes(pdu[address_at : address_at + 2], "big")
        count = 1 if count_at is None else int.from_bytes(pdu[count_at : count_at + 2], "big")
        spans.append((first, first + max(count, 1) - 1))
    return spans


@dataclass(frozen=True, slots=True)
class AccessRule:
    """What one role may do.

    `function_codes` are allowed (nothing else is); `units`, when given, are the only units it may
    address; `addresses`, when given, are inclusive `(first, last)` ranges every data-table address
    of a request must fall in (codes without one, such as 2B, pass on their function code alone);
    `read_only` refuses [`WRITE_FUNCTION_CODES`][aiortu.transport.WRITE_FUNCTION_CODES] even when
    listed; `broadcast`, when given, allows or refuses unit 0 whatever `units` says (None: unit 0
    is one of the units).
    """

    function_codes: frozenset[int]
    units: frozenset[int] | None = None
    addresses: tuple[tuple[int, int], ...] | None = None
    read_only: bool = False
    broadcast: bool | None = None

    def refusal(self, unit: int, pdu: bytes) -> str | None:
        """Why this rule refuses the request `pdu` to `unit`, or None when it allows it."""
        code = pdu[0] if pdu else 0
        if code not in self.function_codes:
            return f"function code 0x{code:02X} is not allowed"
        if self.read_only and code in WRITE_FUNCTION_CODES:
            return f"function code 0x{code:02X} writes and the role is read-only"
        if unit == 0 and self.broadcast is not None:
            if not self.broadcast:
                return "broadcast (unit 0) is not allowed"
        elif self.units is not None and unit not in self.units:
            return f"unit {unit} is not allowed"
        if self.addresses is not None:
            spans = _spans(pdu)
            if spans is None:
                return "the request is too short to tell its addresses"
            for first, last in spans:
                if not any(low <= first and last <= high for low, high in self.addresses):
                    return f"addresses {first}..{last} are outside the allowed ranges"
        return None


@dataclass(frozen=True, slots=True)
class RoleRules:
    """The [`AccessRule`][aiortu.transport.AccessRule] of each role, and the role of a certificate
    that carries none (`default_role`; None: such a client may do nothing)."""

    roles: Mapping[str, AccessRule] = field(default_factory=dict)
    default_role: str | None = None

    def refusal(self, role: str | None, unit: int, pdu: bytes) -> str | None:
        """Why a client of `role` may not send `pdu` to `unit`, or None when it may."""
        if role is None:
            role = self.default_role
            if role is None:
                return "the certificate carries no role and there is no default role"
        rule = self.roles.get(role)
        if rule is None:
            return f"no rule grants the role {role!r} anything"
        return rule.refusal(unit, pdu)


_TOP_KEYS: Final = frozenset({"default_role", "roles"})
_RULE_KEYS: Final = frozenset({"function_codes", "units", "addresses", "read_only", "broadcast"})


def load_rules(path: str | Path) -> RoleRules:
    """Read [`RoleRules`][aiortu.transport.RoleRules] from the TOML file `path` (see the module
    docstring). Raises [`ConfigError`][aiortu.errors.ConfigError] naming the file and the key."""
    source = str(path)
    text = TomlReader.read(path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(source, "(file)", f"not valid TOML ({error})") from None
    return parse_rules(data, source)


def parse_rules(data: Mapping[str, Any], source: str = "rules") -> RoleRules:
    """[`RoleRules`][aiortu.transport.RoleRules] from the parsed TOML `data`; errors name
    `source`."""
    _no_unknown(data, _TOP_KEYS, source, "")
    default = data.get("default_role")
    if default is not None and not isinstance(default, str):
        raise ConfigError(source, "default_role", "must be a role name (a string)")
    roles = data.get("roles", {})
    if not isinstance(roles, dict):
        raise ConfigError(source, "roles", "must be a table of roles")
    rules = {name: _rule(body, source, f"roles.{name}") for name, body in roles.items()}
    return RoleRules(rules, default)


def _no_unknown(table: Mapping[str, Any], known: Iterable[str], source: str, where: str) -> None:
    for key in table:
        if key not in known:
            expected = ", ".join(sorted(known))
            raise ConfigError(source, f"{where}{key}", f"unknown key (expected {expected})")


def _rule(body: Any, source: str, where: str) -> AccessRule:
    if not isinstance(body, dict):
        raise ConfigError(source, where, "must be a table")
    _no_unknown(body, _RULE_KEYS, source, f"{where}.")
    if "function_codes" not in body:
        raise ConfigError(source, f"{where}.function_codes", "is required (default deny)")
    codes = _numbers(body["function_codes"], range(1, 128), source, f"{where}.function_codes")
    units = body.get("units")
    if units is not None:
        units = _numbers(units, range(256), source, f"{where}.units")
    ranges = body.get("addresses")
    if ranges is not None:
        ranges = tuple(
            _range(item, source, f"{where}.addresses")
            for item in _list(ranges, source, f"{where}.addresses")
        )
    read_only = body.get("read_only", False)
    if not isinstance(read_only, bool):
        raise ConfigError(source, f"{where}.read_only", "must be true or false")
    broadcast = body.get("broadcast")
    if broadcast is not None and not isinstance(broadcast, bool):
        raise ConfigError(source, f"{where}.broadcast", "must be true or false")
    return AccessRule(codes, units, ranges, read_only, broadcast)


def _list(value: Any, source: str, key: str) -> list[Any]:
    if not isinstance(value, list):
        raise ConfigError(source, key, "must be a list")
    return value


def _numbers(value: Any, allowed: range, source: str, key: str) -> frozenset[int]:
    numbers = _list(value, source, key)
    for number in numbers:
        if type(number) is not int or number not in allowed:
            bounds = f"{allowed.start}..{allowed.stop - 1}"
            raise ConfigError(source, key, f"{number!r} is not a number in {bounds}")
    return frozenset(numbers)


def _range(item: Any, source: str, key: str) -> tuple[int, int]:
    if (
        not isinstance(item, list)
        or len(item) != 2
        or not all(type(bound) is int and 0 <= bound <= 0xFFFF for bound in item)
        or item[0] > item[1]
    ):
        raise ConfigError(source, key, f"{item!r} is not a [first, last] pair in 0..65535")
    return (item[0], item[1])
