"""The PDUs of the file records: read file record (14) and write file record (15).

A device may expose up to 65535 files (numbered 1..65535) of 10000 records each (numbered
0..9999); a record is a 16-bit register. One PDU carries several sub-requests, each naming
a file, a starting record and a count of records, always with reference type 6. The spec
limits the whole PDU, request and reply alike, to 253 bytes, so the number and size of the
sub-requests is bounded by what fits, and a read request is refused when its reply could
not fit.

The sub-requests are small frozen dataclasses
([`FileRecordRequest`][aiortu.core.pdu.FileRecordRequest],
[`FileRecord`][aiortu.core.pdu.FileRecord]) that only normalise their fields; the PDU carrying
them checks their ranges, so that an error names the sub-request by its index and is an
[`InvalidRequest`][aiortu.errors.InvalidRequest] in a request and an
[`InvalidValue`][aiortu.errors.InvalidValue] in a reply. In decoded requests, a wrong reference
type, file number or record range is exception code 2 (illegal data address); a wrong byte count,
record length or size is exception code 3.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import ClassVar, Self

from aiortu.core.codes import ExceptionCode, FunctionCode
from aiortu.core.errors import MalformedPDU
from aiortu.core.pdu._base import (
    MAX_PDU_LENGTH,
    PDU,
    REGISTER_RANGE,
    Request,
    Response,
    pack_registers,
    unpack_registers,
)

__all__ = (
    "FILE_NUMBER_RANGE",
    "FILE_REFERENCE_TYPE",
    "MAX_READ_SUB_REQUESTS",
    "RECORD_NUMBER_RANGE",
    "FileRecord",
    "FileRecordRequest",
    "ReadFileRecordRequest",
    "ReadFileRecordResponse",
    "WriteFileRecordRequest",
    "WriteFileRecordResponse",
)

FILE_REFERENCE_TYPE = 6
"""The reference type every file sub-request carries."""

FILE_NUMBER_RANGE = range(1, 0x10000)
"""File numbers: 1..65535."""

RECORD_NUMBER_RANGE = range(10000)
"""Record numbers inside a file: 0..9999 (0x270F)."""

_SUB_REQUEST_SIZE = 7
"""Reference type, file number, record number and record length, on the wire."""

MAX_READ_SUB_REQUESTS = (MAX_PDU_LENGTH - 2) // _SUB_REQUEST_SIZE
"""The most sub-requests one read file record request holds (35, byte count 0xF5)."""

_READ_SUB_REQUEST_COUNT = range(1, MAX_READ_SUB_REQUESTS + 1)
_READ_BYTE_COUNT = range(_SUB_REQUEST_SIZE, _SUB_REQUEST_SIZE * MAX_READ_SUB_REQUESTS + 1)
_PDU_LENGTH = range(MAX_PDU_LENGTH + 1)
_RECORD_LENGTH = range(1, len(RECORD_NUMBER_RANGE) + 1)
_RECORD_END = range(len(RECORD_NUMBER_RANGE) + 1)
_MIN_RECORD_COUNT = range(1, MAX_PDU_LENGTH)
_WRITE_BYTE_COUNT = range(_SUB_REQUEST_SIZE + 2, MAX_PDU_LENGTH - 1)


@dataclass(frozen=True, slots=True)
class FileRecordRequest:
    """One sub-request of [`ReadFileRecordRequest`][aiortu.core.pdu.ReadFileRecordRequest]:
    read `record_length` records of file `file_number` from record `record_number`.

    The ranges (file 1..65535, records 0..9999, at least one record, not past record 9999)
    are checked by the request that carries it.
    """

    file_number: int
    record_number: int
    record_length: int


@dataclass(frozen=True, slots=True)
class FileRecord:
    """One sub-record of write file record (15): `values` written to file `file_number`
    from record `record_number`.

    `record_length` is `len(values)`. The ranges (file 1..65535, records 0..9999, at
    least one value, not past record 9999, values 0..65535) are checked by the PDU that
    carries it.
    """

    file_number: int
    record_number: int
    values: tuple[int, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "values", tuple(self.values))

    @property
    def record_length(self) -> int:
        """The number of records (registers) written."""
        return len(self.values)


def _address_problem(
    prefix: str, file_number: int, record_number: int, record_length: int
) -> tuple[str, int, range] | None:
    """The first address field out of range, as (field, value, allowed), or None."""
    if file_number not in FILE_NUMBER_RANGE:
        return f"{prefix}.file_number", file_number, FILE_NUMBER_RANGE
    if record_number not in RECORD_NUMBER_RANGE:
        return f"{prefix}.record_number", record_number, RECORD_NUMBER_RANGE
    if record_length >= 1 and record_number + record_length not in _RECORD_END:
        return f"{prefix}.record_number + record_length", record_number + record_length, _RECORD_END
    return None


def _check_sub_request(
    pdu: PDU, prefix: str, file_number: int, record_number: int, record_length: int
) -> None:
    # record_length goes first: a zero length is a value problem (code 3), and the
    # decoders have already sent the address problems (code 2) their own way.
    pdu._check(f"{prefix}.record_length", record_length, _RECORD_LENGTH)
    problem = _address_problem(prefix, file_number, record_number, record_length)
    if problem is not None:
        raise pdu._invalid(*problem)


def _raise_address(cls: type[PDU], problem: tuple[str, int, range]) -> None:
    field, value, allowed = problem
    raise MalformedPDU(
        f"{cls.__name__}: file record address out of range",
        field=field,
        value=value,
        allowed=allowed,
        exception_code=ExceptionCode.ILLEGAL_DATA_ADDRESS,
    )


def _check_reference_type(cls: type[PDU], prefix: str, reference_type: int) -> None:
    if reference_type != FILE_REFERENCE_TYPE:
        raise MalformedPDU(
            f"{cls.__name__}: reference type",
            field=f"{prefix}.reference_type",
            value=reference_type,
            allowed=range(FILE_REFERENCE_TYPE, FILE_REFERENCE_TYPE + 1),
            exception_code=ExceptionCode.ILLEGAL_DATA_ADDRESS,
        )


# ---------------------------------------------------------------------------------------
# 14 Read File Record


@dataclass(frozen=True, slots=True)
class ReadFileRecordResponse(Response):
    """Reply to read file record: for each sub-request, in order, the records read.

    `records` is one tuple of register values (at least one) per sub-request. Each travels
    as a length byte, reference type 6 and the words; the whole PDU fits 253 bytes.
    """

    function_code: ClassVar[int] = FunctionCode.READ_FILE_RECORD
    records: tuple[tuple[int, ...], ...]

    def __post_init__(self) -> None:
        records = tuple(tuple(values) for values in self.records)
        object.__setattr__(self, "records", records)
        self._check("len(records)", len(records), _MIN_RECORD_COUNT)
        for index, values in enumerate(records):
            self._check(f"len(records[{index}])", len(values), _MIN_RECORD_COUNT)
            self._check_values(f"records[{index}]", values, REGISTER_RANGE)
        self._check("len(PDU)", _read_response_length(map(len, records)), _PDU_LENGTH)

    def encode(self) -> bytes:
        body = b"".join(
            bytes((1 + 2 * len(values), FILE_REFERENCE_TYPE)) + pack_registers(values)
            for values in self.records
        )
        return bytes((self.function_code, len(body))) + body

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_function_code(pdu)
        cls._expect_min_length(pdu, 5)
        cls._expect_length(pdu, 2 + pdu[1])
        records: list[tuple[int, ...]] = []
        position = 2
        while position < len(pdu):
            index = len(records)
            length = pdu[position]
            if length % 2 == 0 or length < 3 or position + 1 + length > len(pdu):
                raise MalformedPDU(
                    cls.__name__,
                    field=f"records[{index}] length",
                    value=length,
                    allowed=range(3, len(pdu) - position, 2),
                )
            _check_reference_type(cls, f"records[{index}]", pdu[position + 1])
            records.append(unpack_registers(pdu, position + 2, (length - 1) // 2))
            position += 1 + length
        return cls._build(lambda: cls(tuple(records)))


def _read_response_length(record_lengths: Iterable[int]) -> int:
    # Each sub-response costs a length byte, the reference type and two bytes a record.
    return 2 + sum(2 + 2 * length for length in record_lengths)


@dataclass(frozen=True, slots=True)
class ReadFileRecordRequest(Request):
    """Read file records: 1..35 [`FileRecordRequest`][aiortu.core.pdu.FileRecordRequest]
    sub-requests in one PDU.

    Each reads 1 or more records of a file (1..65535) from a record number (0..9999), not
    past record 9999. The reply to the whole request must fit 253 bytes, so the record
    lengths add up to at most 124 minus the sub-request count.
    """

    function_code: ClassVar[int] = FunctionCode.READ_FILE_RECORD
    response_class: ClassVar[type[Response]] = ReadFileRecordResponse
    sub_requests: tuple[FileRecordRequest, ...]

    def __post_init__(self) -> None:
        sub_requests = tuple(self.sub_requests)
        object.__setattr__(self, "sub_requests", sub_requests)
        self._check("len(sub_requests)", len(sub_requests), _READ_SUB_REQUEST_COUNT)
        for index, sub in enumerate(sub_requests):
            _check_sub_request(
                self,
                f"sub_requests[{index}]",
                sub.file_number,
                sub.record_number,
                sub.record_length,
            )
        self._check(
            "len(response PDU)",
            _read_response_length(sub.record_length for sub in sub_requests),
            _PDU_LENGTH,
        )

    def encode(self) -> bytes:
        body = b"".join(
            bytes((FILE_REFERENCE_TYPE,))
            + pack_registers((sub.file_number, sub.record_number, sub.record_length))
            for sub in self.sub_requests
        )
        return bytes((self.function_code, len(body))) + body

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_function_code(pdu)
        cls._expect_min_length(pdu, 2 + _SUB_REQUEST_SIZE)
        byte_count = pdu[1]
        if byte_count not in _READ_BYTE_COUNT or byte_count % _SUB_REQUEST_SIZE:
            raise MalformedPDU(
                cls.__name__,
                field="byte_count",
                value=byte_count,
                allowed=range(_READ_BYTE_COUNT.start, _READ_BYTE_COUNT.stop, _SUB_REQUEST_SIZE),
            )
        cls._expect_length(pdu, 2 + byte_count)
        sub_requests = []
        for index, position in enumerate(range(2, len(pdu), _SUB_REQUEST_SIZE)):
            prefix = f"sub_requests[{index}]"
            _check_reference_type(cls, prefix, pdu[position])
            fields = unpack_registers(pdu, position + 1, 3)
            problem = _address_problem(prefix, *fields)
            if problem is not None:
                _raise_address(cls, problem)
            sub_requests.append(FileRecordRequest(*fields))
        return cls._build(lambda: cls(tuple(sub_requests)))

    def check_response(self, response: Response) -> None:
        Request.check_response(self, response)
        assert isinstance(response, ReadFileRecordResponse)
        if len(response.records) != len(self.sub_requests):
            raise MalformedPDU(
                "reply sub-response count differs from the sub-requests",
                field="len(records)",
                value=len(response.records),
                allowed=range(len(self.sub_requests), len(self.sub_requests) + 1),
            )
        for index, (sub, values) in enumerate(
            zip(self.sub_requests, response.records, strict=True)
        ):
            if len(values) != sub.record_length:
                raise MalformedPDU(
                    "reply record count differs from the record length asked",
                    field=f"len(records[{index}])",
                    value=len(values),
                    allowed=range(sub.record_length, sub.record_length + 1),
                )


# ---------------------------------------------------------------------------------------
# 15 Write File Record


def _check_records(pdu: PDU, records: tuple[FileRecord, ...]) -> None:
    pdu._check("len(records)", len(records), _MIN_RECORD_COUNT)
    for index, record in enumerate(records):
        prefix = f"records[{index}]"
        _check_sub_request(
            pdu, prefix, record.file_number, record.record_number, record.record_length
        )
        pdu._check_values(f"{prefix}.values", record.values, REGISTER_RANGE)
    length = 2 + sum(_SUB_REQUEST_SIZE + 2 * record.record_length for record in records)
    pdu._check("len(PDU)", length, _PDU_LENGTH)


def _encode_records(function_code: int, records: tuple[FileRecord, ...]) -> bytes:
    body = b"".join(
        bytes((FILE_REFERENCE_TYPE,))
        + pack_registers((record.file_number, record.record_number, record.record_length))
        + pack_registers(record.values)
        for record in records
    )
    return bytes((function_code, len(body))) + body


def _decode_records(cls: type[PDU], pdu: bytes) -> tuple[FileRecord, ...]:
    cls._expect_min_length(pdu, 2 + _SUB_REQUEST_SIZE + 2)
    byte_count = pdu[1]
    if byte_count not in _WRITE_BYTE_COUNT:
        raise MalformedPDU(
            cls.__name__, field="byte_count", value=byte_count, allowed=_WRITE_BYTE_COUNT
        )
    cls._expect_length(pdu, 2 + byte_count)
    records: list[FileRecord] = []
    position = 2
    while position < len(pdu):
        prefix = f"records[{len(records)}]"
        if position + _SUB_REQUEST_SIZE > len(pdu):
            raise MalformedPDU(
                f"{cls.__name__}: sub-record header cut short by the byte count",
                field=f"{prefix} header",
                value=len(pdu) - position,
                allowed=f"{_SUB_REQUEST_SIZE} bytes",
            )
        _check_reference_type(cls, prefix, pdu[position])
        file_number, record_number, record_length = unpack_registers(pdu, position + 1, 3)
        end = position + _SUB_REQUEST_SIZE + 2 * record_length
        if end > len(pdu):
            raise MalformedPDU(
                f"{cls.__name__}: record data cut short by the byte count",
                field=f"{prefix}.record_length",
                value=record_length,
                allowed=range((len(pdu) - position - _SUB_REQUEST_SIZE) // 2 + 1),
            )
        problem = _address_problem(prefix, file_number, record_number, record_length)
        if problem is not None:
            _raise_address(cls, problem)
        values = unpack_registers(pdu, position + _SUB_REQUEST_SIZE, record_length)
        records.append(FileRecord(file_number, record_number, values))
        position = end
    return tuple(records)


@dataclass(frozen=True, slots=True)
class WriteFileRecordResponse(Response):
    """Reply to write file record: an exact echo of the request's sub-records."""

    function_code: ClassVar[int] = FunctionCode.WRITE_FILE_RECORD
    records: tuple[FileRecord, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "records", tuple(self.records))
        _check_records(self, self.records)

    def encode(self) -> bytes:
        return _encode_records(self.function_code, self.records)

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_function_code(pdu)
        records = _decode_records(cls, pdu)
        return cls._build(lambda: cls(records))


@dataclass(frozen=True, slots=True)
class WriteFileRecordRequest(Request):
    """Write file records: one or more [`FileRecord`][aiortu.core.pdu.FileRecord] sub-records
    in one PDU.

    Each writes 1 or more values (0..65535) to a file (1..65535) from a record number
    (0..9999), not past record 9999; the whole PDU fits 253 bytes (so at most 122 values
    in one sub-record). The reply echoes the request. May be broadcast.
    """

    function_code: ClassVar[int] = FunctionCode.WRITE_FILE_RECORD
    response_class: ClassVar[type[Response]] = WriteFileRecordResponse
    broadcastable: ClassVar[bool] = True
    records: tuple[FileRecord, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "records", tuple(self.records))
        _check_records(self, self.records)

    def encode(self) -> bytes:
        return _encode_records(self.function_code, self.records)

    @classmethod
    def decode(cls, pdu: bytes) -> Self:
        cls._expect_function_code(pdu)
        records = _decode_records(cls, pdu)
        return cls._build(lambda: cls(records))

    def check_response(self, response: Response) -> None:
        Request.check_response(self, response)
        assert isinstance(response, WriteFileRecordResponse)
        if response.records != self.records:
            raise MalformedPDU(
                "reply does not echo the request",
                field="records",
                value=response.records,
                allowed=self.records,
            )
