"""Sparkplug B payloads: the `Payload` and `Metric` messages of the Sparkplug B
specification, written and read by a small protobuf codec of the few fields used.

The fields and their numbers are those of the specification's `sparkplug_b.proto`
(Sparkplug 3.0, chapter 6): a payload's `timestamp` (1), `metrics` (2) and `seq` (3); a
metric's `name` (1), `alias` (2), `timestamp` (3), `datatype` (4), `is_historical` (5),
`is_null` (7) and its value in `int_value` (10, Int8..UInt32), `long_value` (11, Int64 and
UInt64), `float_value` (12), `double_value` (13), `boolean_value` (14) or `string_value`
(15). Signed values go two's complement in the unsigned fields, in their own width.
Unknown fields are skipped when reading.
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass

__all__ = ("DataType", "Metric", "SparkplugPayload", "decode_payload", "encode_payload")


class DataType(enum.IntEnum):
    """The Sparkplug B data types the bridge uses (the specification's numbers)."""

    INT16 = 2
    INT32 = 3
    INT64 = 4
    UINT16 = 6
    UINT32 = 7
    UINT64 = 8
    FLOAT = 9
    DOUBLE = 10
    BOOLEAN = 11
    STRING = 12


_INT_FIELD = {DataType.INT16, DataType.INT32, DataType.UINT16, DataType.UINT32}
_SIGNED_BITS = {DataType.INT16: 16, DataType.INT32: 32, DataType.INT64: 64}
"""A signed value goes in the unsigned field as its two's complement in its own width
(Int16 -1 is 0xFFFF), as pysparkplug reads it."""


@dataclass(frozen=True, slots=True)
class Metric:
    """One Sparkplug B metric: `name`, `datatype`, `value` (None: `is_null`), `timestamp`
    (ms since the epoch; None: the payload's), `alias`, `is_historical`."""

    name: str
    datatype: DataType
    value: bool | int | float | str | None
    timestamp: int | None = None
    alias: int | None = None
    is_historical: bool = False


@dataclass(frozen=True, slots=True)
class SparkplugPayload:
    """A Sparkplug B payload: `timestamp` (ms), `metrics` and `seq` (None: none)."""

    timestamp: int
    metrics: tuple[Metric, ...]
    seq: int | None = None


def _varint(n: int) -> bytes:
    out = bytearray()
    while True:
        byte = n & 0x7F
        n >>= 7
        if n:
            out.append(byte | 0x80)
        else:
            out.append(byte)
            return bytes(out)


def _key(field: int, wire: int) -> bytes:
    return _varint(field << 3 | wire)


def _length_delimited(field: int, data: bytes) -> bytes:
    return _key(field, 2) + _varint(len(data)) + data


def _value(metric: Metric) -> bytes:
    value, datatype = metric.value, metric.datatype
    if value is None:
        return _key(7, 0) + b"\x01"
    if datatype is DataType.BOOLEAN:
        return _key(14, 0) + (b"\x01" if value else b"\x00")
    if datatype is DataType.STRING:
        return _length_delimited(15, str(value).encode())
    if datatype is DataType.FLOAT:
        return _key(12, 5) + struct.pack("<f", float(value))
    if datatype is DataType.DOUBLE:
        return _key(13, 1) + struct.pack("<d", float(value))
    mask = (1 << _SIGNED_BITS.get(datatype, 64)) - 1
    return _key(10 if datatype in _INT_FIELD else 11, 0) + _varint(int(value) & mask)


def _metric(metric: Metric) -> bytes:
    data = _length_delimited(1, metric.name.encode())
    if metric.alias is not None:
        data += _key(2, 0) + _varint(metric.alias)
    if metric.timestamp is not None:
        data += _key(3, 0) + _varint(metric.timestamp)
    data += _key(4, 0) + _varint(metric.datatype)
    if metric.is_historical:
        data += _key(5, 0) + b"\x01"
    return data + _value(metric)


def encode_payload(payload: SparkplugPayload) -> bytes:
    """`payload` in protobuf's wire format."""
    data = bytearray(_key(1, 0) + _varint(payload.timestamp))
    for metric in payload.metrics:
        data += _length_delimited(2, _metric(metric))
    if payload.seq is not None:
        data += _key(3, 0) + _varint(payload.seq)
    return bytes(data)


def _fields(data: bytes) -> list[tuple[int, int, int | bytes]]:
    """The `(field, wire type, value)` of each field in `data`."""
    fields: list[tuple[int, int, int | bytes]] = []
    at = 0

    def varint() -> int:
        nonlocal at
        n = shift = 0
        while True:
            byte = data[at]
            at += 1
            n |= (byte & 0x7F) << shift
            if not byte & 0x80:
                return n
            shift += 7

    while at < len(data):
        key = varint()
        field, wire = key >> 3, key & 7
        value: int | bytes
        if wire == 0:
            value = varint()
        elif wire == 1:
            value, at = data[at : at + 8], at + 8
        elif wire == 5:
            value, at = data[at : at + 4], at + 4
        elif wire == 2:
            length = varint()
            value, at = data[at : at + length], at + length
        else:
            raise ValueError(f"protobuf wire type {wire} is not used by Sparkplug B")
        fields.append((field, wire, value))
    if at != len(data):
        raise ValueError("a truncated protobuf message")
    return fields


def _signed(n: int, bits: int) -> int:
    return n - (1 << bits) if n >> (bits - 1) else n


def _decode_metric(data: bytes) -> Metric:
    name, datatype, alias, timestamp = "", 0, None, None
    value: bool | int | float | str | None = None
    for field, _, raw in _fields(data):
        if field == 1 and isinstance(raw, bytes):
            name = raw.decode()
        elif field == 2 and isinstance(raw, int):
            alias = raw
        elif field == 3 and isinstance(raw, int):
            timestamp = raw
        elif field == 4 and isinstance(raw, int):
            datatype = raw
        elif field in (10, 11) and isinstance(raw, int):
            value = raw
        elif field == 12 and isinstance(raw, bytes):
            value = struct.unpack("<f", raw)[0]
        elif field == 13 and isinstance(raw, bytes):
            value = struct.unpack("<d", raw)[0]
        elif field == 14 and isinstance(raw, int):
            value = bool(raw)
        elif field == 15 and isinstance(raw, bytes):
            value = raw.decode()
    try:
        kind = DataType(datatype)
    except ValueError:
        raise ValueError(
            f"metric {name!r}: Sparkplug datatype {datatype} is not supported"
        ) from None
    bits = _SIGNED_BITS.get(kind)
    if bits is not None and isinstance(value, int) and not isinstance(value, bool):
        value = _signed(value & ((1 << bits) - 1), bits)
    return Metric(name, kind, value, timestamp, alias)


def decode_payload(data: bytes) -> SparkplugPayload:
    """The payload in `data`; ValueError when it is not one."""
    try:
        timestamp, metrics, seq = 0, [], None
        for field, _, raw in _fields(data):
            if field == 1 and isinstance(raw, int):
                timestamp = raw
            elif field == 2 and isinstance(raw, bytes):
                metrics.append(_decode_metric(raw))
            elif field == 3 and isinstance(raw, int):
                seq = raw
    except (IndexError, struct.error, UnicodeDecodeError) as error:
        raise ValueError(f"not a Sparkplug B payload: {error}") from None
    return SparkplugPayload(timestamp, tuple(metrics), seq)
