"""The sub-requests and sub-records of the file record functions (14 and 15), as a caller
gives them (the classes or plain tuples), checked before anything is sent."""

from __future__ import annotations

from collections.abc import Sequence

from aiortu.core import pdu
from aiortu.core.errors import InvalidRequest
from aiortu.master._arguments import check_int, check_items, check_registers

__all__ = (
    "FileRecordLike",
    "RecordRequestLike",
    "as_file_record",
    "as_record_request",
    "file_records",
    "record_requests",
)

RecordRequestLike = pdu.FileRecordRequest | tuple[int, int, int]
"""A read file record sub-request: the class, or `(file, record, length)`."""

FileRecordLike = pdu.FileRecord | tuple[int, int, Sequence[int]]
"""A write file record sub-record: the class, or `(file, record, values)`."""


def _fields(name: str, item: object, kind: type, names: tuple[str, str, str]) -> tuple[object, ...]:
    """The three fields of `item`, an instance of `kind` or a tuple of three."""
    if isinstance(item, kind):
        return tuple(getattr(item, field) for field in names)
    if not isinstance(item, tuple | list) or len(item) != 3:
        raise InvalidRequest(name, item, f"a {kind.__name__} or ({', '.join(names)})")
    return tuple(item)


def as_record_request(sub: RecordRequestLike) -> pdu.FileRecordRequest:
    """A read file record sub-request from the class or a `(file, record, length)` tuple."""
    names = ("file_number", "record_number", "record_length")
    fields = _fields("sub_request", sub, pdu.FileRecordRequest, names)
    for name, value in zip(names, fields, strict=True):
        check_int(name, value, range(0x10000), InvalidRequest)
    if isinstance(sub, pdu.FileRecordRequest):
        return sub
    return pdu.FileRecordRequest(*sub)


def as_file_record(record: FileRecordLike) -> pdu.FileRecord:
    """A write file record sub-record from the class or a `(file, record, values)` tuple."""
    names = ("file_number", "record_number", "values")
    file_number, record_number, values = _fields("record", record, pdu.FileRecord, names)
    check_int("file_number", file_number, range(0x10000), InvalidRequest)
    check_int("record_number", record_number, range(0x10000), InvalidRequest)
    return pdu.FileRecord(
        file_number,  # type: ignore[arg-type]  # checked above
        record_number,  # type: ignore[arg-type]
        check_registers("values", values),
    )


def record_requests(sub_requests: object) -> tuple[pdu.FileRecordRequest, ...]:
    """The sub-requests of a read file record (14), each checked."""
    items = check_items("sub_requests", sub_requests, "an iterable of sub-requests")
    return tuple(as_record_request(sub) for sub in items)  # type: ignore[arg-type]


def file_records(records: object) -> tuple[pdu.FileRecord, ...]:
    """The sub-records of a write file record (15), each checked."""
    items = check_items("records", records, "an iterable of records")
    return tuple(as_file_record(record) for record in items)  # type: ignore[arg-type]
