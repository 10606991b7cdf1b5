"""The line server's byte shortcut: a register read goes to the line as the bytes it came in,
and its reply back to the client as the bytes the device sent.

On the general route (`request_of` in `_forward.py`) a client's request PDU is decoded into its
class, the master encodes that into the RTU frame, and the device's reply is decoded into a
response that the gateway encodes again for the client. For a register read the spec allows,
every step gives back the bytes it started from, so the line's `ReadsAsBytes` makes it a
[`RawRegisterRead`][aiortu.core.pdu.RawRegisterRead] instead, where its predicate
`ReadsAsBytes.forwards` allows:

- its PDU goes into the RTU frame as it is (the gateway has checked the access rules and the
  unit before; the predicate checks the function code, the length, the count and the
  address range, which decoding would check);
- its usual reply comes back as a [`RawPDU`][aiortu.core.pdu.RawPDU] of the reply's bytes,
  which the gateway puts into the MBAP header as they are, once the master has made the
  checks it makes on the general route: the CRC, the unit, the function code or its
  exception form, a byte count of twice the count asked, and that many bytes. A reply that
  is not the usual one goes through the master's table as on the general route; exceptions,
  timeouts, late and malformed replies end the same way.

Each distinct read is made once per line (a poll loop sends the same bytes again and again),
so the master finds its frame, and its last reply, again: the request is neither decoded nor
encoded, and a reply that comes back the same is neither decoded nor its CRC computed again.

The cache and coalescing key on the request's and the reply's bytes, which are the same on
both routes, so both keep working unchanged. `tests/gateway/test_as_bytes_differential.py`
plays seeded sessions of replies, exceptions, timeouts, late, malformed and garbled replies
with the predicate on and off and compares the bytes each client gets.
"""

from __future__ import annotations

import struct
from typing import Final

from aiortu.core.codes import FunctionCode
from aiortu.core.pdu import ADDRESS_RANGE, MAX_READ_REGISTERS, RawRegisterRead, Request
from aiortu.errors import InvalidValue
from aiortu.gateway._forward import request_of
from aiortu.master import Master

__all__ = ("ReadsAsBytes",)

_CODES: Final = frozenset((FunctionCode.READ_HOLDING_REGISTERS, FunctionCode.READ_INPUT_REGISTERS))
_ADDRESS_COUNT: Final = struct.Struct(">HH")
_ADDRESSES: Final = ADDRESS_RANGE.stop
_MAX_READS: Final = 1024
"""Distinct reads kept per line; past that the memo starts again (a bound, not a policy)."""


class ReadsAsBytes:
    """The byte shortcut of the line of `master` (see the module docstring)."""

    __slots__ = ("_reads", "runs_its_line")

    def __init__(self, master: Master) -> None:
        self.runs_its_line = _runs_its_line(master)
        """Whether the master runs its own line: its engine takes a read kept as bytes."""
        self._reads: dict[bytes, RawRegisterRead] = {}

    def forwards(self, pdu: bytes) -> bool:
        """The predicate: whether request `pdu` goes to the line as its bytes. It does when

        - the master runs its own line (a [`Seam`][aiortu.master.Seam] given in its place,
          such as a [`MockLine`][aiortu.testing.MockLine], gets the decoded request its
          handler expects);
        - `pdu` is a read of holding (03) or input (04) registers of exactly five bytes, of
          1..125 registers within the address space: what decodes into a register read.

        Anything else takes the general route."""
        if not self.runs_its_line or len(pdu) != 5 or pdu[0] not in _CODES:
            return False
        address, count = _ADDRESS_COUNT.unpack_from(pdu, 1)
        return bool(0 < count <= MAX_READ_REGISTERS and address + count <= _ADDRESSES)

    def request(self, pdu: bytes) -> Request:
        """The request to send for read `pdu`: a read kept as its bytes, made once per
        distinct PDU, where `forwards` allows; else `request_of`'s."""
        read = self._reads.get(pdu)
        if read is not None:
            return read
        if not self.forwards(pdu):
            return request_of(pdu)
        if len(self._reads) >= _MAX_READS:
            self._reads.clear()
        read = self._reads[pdu] = RawRegisterRead(pdu[0], pdu[1:])
        return read


def _runs_its_line(master: Master) -> bool:
    try:
        master.engine  # noqa: B018  (raises for a Seam given in place of a stream)
    except InvalidValue:
        return False
    return True
