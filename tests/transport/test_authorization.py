"""Access rules against an oracle built from the core's decoded requests: every request of
every public function code, random rules, the same verdict."""

from __future__ import annotations

from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st

from aiortu.core.pdu import PDU, ReadWriteMultipleRegistersRequest
from aiortu.transport import WRITE_FUNCTION_CODES, AccessRule, RoleRules
from tests.core.frame_strategies import REQUEST_STRATEGIES

requests = st.one_of(*REQUEST_STRATEGIES.values())
codes = st.frozensets(st.integers(1, 127), max_size=12) | st.frozensets(
    st.sampled_from([1, 2, 3, 4, 5, 6, 8, 15, 16, 22, 23, 24, 43])
)
spans = st.tuples(st.integers(0, 0xFFFF), st.integers(0, 0xFFFF)).map(
    lambda pair: tuple(sorted(pair))
)
rules = st.builds(
    AccessRule,
    function_codes=codes,
    units=st.none() | st.frozensets(st.integers(0, 255), max_size=5),
    addresses=st.none() | st.lists(spans, max_size=3).map(tuple),
    read_only=st.booleans(),
    broadcast=st.none() | st.booleans(),
)


def _touched(request: PDU) -> list[tuple[int, int]]:
    """The data-table addresses a request touches, from its decoded fields."""
    if isinstance(request, ReadWriteMultipleRegistersRequest):
        return [
            (request.read_address, request.read_address + request.read_count - 1),
            (request.write_address, request.write_address + len(request.values) - 1),
        ]
    fields: dict[str, Any] = {
        name: getattr(request, name, None) for name in ("address", "count", "values")
    }
    if fields["address"] is None or request.function_code == 0x08:
        return []
    if fields["count"] is not None:
        count = fields["count"]
    elif isinstance(fields["values"], tuple | list):
        count = len(fields["values"])
    else:
        count = 1
    return [(fields["address"], fields["address"] + count - 1)]


def _near(request: PDU) -> st.SearchStrategy[tuple[tuple[int, int], ...]]:
    """Address ranges that end around the request's own: inside, just short, just over."""
    touched = _touched(request) or [(0, 0)]
    edges = st.sampled_from(touched).flatmap(
        lambda span: st.tuples(
            st.integers(max(span[0] - 2, 0), span[0] + 1),
            st.integers(max(span[1] - 1, 0), min(span[1] + 2, 0xFFFF)),
        )
    )
    return st.lists(edges.map(lambda pair: tuple(sorted(pair))), min_size=1, max_size=3).map(tuple)


@settings(max_examples=400)
@given(rules, requests, st.integers(0, 255) | st.just(0), st.data())
def test_a_rule_allows_exactly_what_it_grants(
    rule: AccessRule, request: PDU, unit: int, data: st.DataObject
) -> None:
    if rule.addresses is not None and data.draw(st.booleans()):
        # Ranges that end around the request's own: inside, just short, just over.
        rule = AccessRule(
            rule.function_codes,
            rule.units,
            data.draw(_near(request)),
            rule.read_only,
            rule.broadcast,
        )
    code = request.function_code
    if unit == 0 and rule.broadcast is not None:
        unit_allowed = rule.broadcast
    else:
        unit_allowed = rule.units is None or unit in rule.units
    expected = (
        code in rule.function_codes
        and not (rule.read_only and code in WRITE_FUNCTION_CODES)
        and unit_allowed
        and (
            rule.addresses is None
            or all(
                any(low <= first and last <= high for low, high in rule.addresses)
                for first, last in _touched(request)
            )
        )
    )
    refusal = rule.refusal(unit, request.encode())
    assert (refusal is None) == expected, (rule, request, refusal)
    if refusal is not None:
        assert "\n" not in refusal


@given(requests, st.integers(0, 255))
def test_default_deny(request: PDU, unit: int) -> None:
    pdu = request.encode()
    assert RoleRules().refusal("anyone", unit, pdu) is not None
    assert RoleRules().refusal(None, unit, pdu) is not None
    everything = AccessRule(frozenset(range(1, 128)))
    assert RoleRules({"x": everything}).refusal(None, unit, pdu) is not None
    assert RoleRules({"x": everything}, default_role="x").refusal(None, unit, pdu) is None


def test_broadcast_alone_decides_unit_0() -> None:
    read = bytes.fromhex("0300000001")
    units = frozenset({0, 1})
    assert AccessRule(frozenset({3}), units, broadcast=False).refusal(0, read) is not None
    assert AccessRule(frozenset({3}), units, broadcast=False).refusal(1, read) is None
    assert AccessRule(frozenset({3}), frozenset({1}), broadcast=True).refusal(0, read) is None
    assert AccessRule(frozenset({3}), frozenset({1})).refusal(0, read) is not None
    assert AccessRule(frozenset({3})).refusal(0, read) is None
