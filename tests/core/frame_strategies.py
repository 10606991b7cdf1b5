"""Hypothesis strategies for whole RTU frames, shared by the frame and receiver tests.

The PDUs come from the per-module PDU strategies, so every function code with a class is
covered; exception replies and user-defined function codes are added here.
"""

from __future__ import annotations

from dataclasses import dataclass

from hypothesis import strategies as st
from hypothesis.strategies import SearchStrategy

from aiortu.core.codes import USER_DEFINED_FUNCTION_CODES, FunctionCode
from aiortu.core.pdu import PDU, DiagnosticsRequest, DiagnosticsResponse
from aiortu.core.rtu import (
    MIN_FRAME_LENGTH,
    crc16,
    encode_frame,
    expected_request_length,
    expected_response_length,
)

from . import strategies_bits_registers as bits_registers
from . import strategies_serial_files_devid as serial_files_devid

REQUEST_STRATEGIES: dict[type, SearchStrategy[PDU]] = {
    **bits_registers.REQUEST_STRATEGIES,
    **serial_files_devid.REQUEST_STRATEGIES,
}
RESPONSE_STRATEGIES: dict[type, SearchStrategy[PDU]] = {
    **bits_registers.RESPONSE_STRATEGIES,
    **serial_files_devid.RESPONSE_STRATEGIES,
}

units = st.integers(1, 247)


@dataclass(frozen=True)
class Sample:
    """One frame on the wire and what a predictor should say about it."""

    frame: bytes
    reply: bool
    predictable: bool
    """Whether the frame's layout gives its length (see :func:`is_predictable`)."""

    @property
    def unit(self) -> int:
        return self.frame[0]


def is_predictable(pdu: PDU) -> bool:
    """Whether the predictors must give exactly this PDU's frame length.

    Diagnostics is predicted as 8 bytes (sub-function and one data word); return query
    data and the sub-functions the spec does not define for a serial line may carry any
    amount of data, and such frames are ended by silence.
    """
    if isinstance(pdu, DiagnosticsRequest | DiagnosticsResponse):
        return len(pdu.data) == 2
    return True


def has_accidental_prefix(frame: bytes) -> bool:
    """Whether a shorter length that either layout predicts for *frame* happens to have a
    good CRC (about one frame in 65,536 of those that can be read both ways).

    A receiver that may expect both layouts (a monitor, or a slave hearing other units)
    completes a frame at the first predicted length whose CRC checks, so it splits such a
    frame in two: a documented limit of length-aware completion (see
    :mod:`aiortu.core.rtu._receiver`), which tests of whole conversations leave out.
    """
    return any(
        MIN_FRAME_LENGTH <= guess < len(frame) and crc16(frame[:guess]) == 0
        for end in range(2, min(len(frame), 12) + 1)
        for guess in (expected_request_length(frame[:end]), expected_response_length(frame[:end]))
    )


def _sample(pdu: PDU, unit: int, reply: bool) -> Sample:
    return Sample(encode_frame(unit, pdu.encode()), reply, is_predictable(pdu))


request_pdus: SearchStrategy[PDU] = st.one_of(*REQUEST_STRATEGIES.values())
response_pdus: SearchStrategy[PDU] = st.one_of(*RESPONSE_STRATEGIES.values())


def requests(unit: SearchStrategy[int] = units) -> SearchStrategy[Sample]:
    """Request frames of every function code with a class, to *unit*."""
    return st.builds(_sample, request_pdus, unit, st.just(False))


def exception_pdus() -> SearchStrategy[bytes]:
    codes = st.sampled_from([int(code) for code in FunctionCode])
    return st.builds(lambda code, exc: bytes((code | 0x80, exc)), codes, st.integers(1, 255))


def responses(unit: SearchStrategy[int] = units) -> SearchStrategy[Sample]:
    """Reply frames of every function code with a class, and exception replies, from *unit*."""
    normal = st.builds(_sample, response_pdus, unit, st.just(True))
    exceptions = st.builds(
        lambda pdu, unit: Sample(encode_frame(unit, pdu), True, True), exception_pdus(), unit
    )
    return st.one_of(normal, exceptions)


def custom_pdus() -> SearchStrategy[bytes]:
    """PDUs of the user-defined function codes, whose length only silence tells."""
    codes = st.sampled_from(USER_DEFINED_FUNCTION_CODES)
    return st.builds(lambda code, data: bytes((code,)) + data, codes, st.binary(max_size=40))


def customs(unit: SearchStrategy[int] = units, reply: bool = False) -> SearchStrategy[Sample]:
    return st.builds(
        lambda pdu, unit: Sample(encode_frame(unit, pdu), reply, False), custom_pdus(), unit
    )
