"""Malformed requests with good CRCs against a slave, and the check of its answers.

Shared by the fault suite (hypothesis draws the arguments of :func:`malformed_pdu`) and
``benchmarks/soak_faults.py`` (a seeded :class:`random.Random` draws them).
"""

from __future__ import annotations

import random
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass

import anyio

from aiortu.core.codes import EXCEPTION_BIT, ExceptionCode, FunctionCode
from aiortu.core.errors import ModbusError
from aiortu.core.pdu import Response, decode_request, decode_response
from aiortu.core.rtu import crc16, encode_frame
from aiortu.slave import Block, MemoryStore, ServerId, Slave
from aiortu.testing import virtual_pair
from tests.slave.helpers import RawMaster

__all__ = (
    "CODES",
    "KINDS",
    "OTHER_UNITS",
    "PROBE_UNIT",
    "UNIT",
    "SlaveUnderTest",
    "check_answers",
    "draw_malformed",
    "malformed_pdu",
    "slave_under_test",
)

UNIT = 17
"""The unit the fuzzed frames go to."""
PROBE_UNIT = 18
"""A second unit of the same slave: its read marks the end of the answers to a frame."""
OTHER_UNITS = (0, 5, 19, 247)
"""Broadcast and units the slave does not serve: never answered."""

CODES: tuple[int, ...] = (*FunctionCode, 0x00, 0x41, 0x64, 0x7F, 0x80, 0x83, 0xFF)
"""Every public function code, user-defined ones, and codes a request may not carry."""

# One well-formed request per public code, the raw material of the malformed ones.
_EXAMPLES: dict[int, bytes] = {
    code: bytes.fromhex(text)
    for code, text in {
        0x01: "01 00 13 00 13",
        0x02: "02 00 C4 00 16",
        0x03: "03 00 6B 00 03",
        0x04: "04 00 08 00 01",
        0x05: "05 00 AC FF 00",
        0x06: "06 00 01 00 03",
        0x07: "07",
        0x08: "08 00 00 A5 37",
        0x0B: "0B",
        0x0C: "0C",
        0x0F: "0F 00 13 00 0A 02 CD 01",
        0x10: "10 00 01 00 02 04 00 0A 01 02",
        0x11: "11",
        0x14: "14 07 06 00 01 00 00 00 02",
        0x15: "15 09 06 00 01 00 00 00 01 12 34",
        0x16: "16 00 04 00 F2 00 25",
        0x17: "17 00 03 00 06 00 0E 00 03 06 00 FF 00 FF 00 FF",
        0x18: "18 04 DE",
        0x2B: "2B 0E 01 00",
    }.items()
}

KINDS = ("noise", "truncated", "extended", "count", "extreme", "byte")
"""How :func:`malformed_pdu` spoils a request."""


def malformed_pdu(code: int, kind: str, noise: bytes, position: int) -> bytes:
    """A request PDU of function code *code*, spoiled the way *kind* says, with the
    random bytes *noise* and a *position* (any int; taken modulo the length)."""
    body = _EXAMPLES.get(code, bytes((code,)) + noise[:4])[1:]
    if kind == "noise":
        body = noise
    elif kind == "truncated":
        body = body[: position % (len(body) + 1)]
    elif kind == "extended":
        body = body + noise
    elif kind == "count" and len(body) >= 2:
        # Spoil a length or count field: the last byte of the fixed part.
        index = min(4, len(body) - 1) if code in (0x0F, 0x10, 0x17) else position % len(body)
        body = body[:index] + bytes((noise[0] if noise else 0,)) + body[index + 1 :]
    elif kind == "extreme" and len(body) >= 4:
        extreme = (b"\xff\xff", b"\x00\x00", b"\x7f\xff", b"\x00\x01")[position % 4]
        start = 2 * (position // 4 % (len(body) // 2))
        body = body[:start] + extreme + body[start + 2 :]
    elif kind == "byte" and body:
        index = position % len(body)
        body = body[:index] + bytes(((body[index] ^ (noise[0] if noise else 0xFF)) or 1,))
        body += _EXAMPLES.get(code, b"\x00" * (index + 2))[index + 2 :]
    return bytes((code,)) + body[:250]


def draw_malformed(rng: random.Random) -> tuple[int, bytes]:
    """A unit (mostly :data:`UNIT`) and a malformed request PDU, drawn from *rng*."""
    unit = UNIT if rng.random() < 0.8 else rng.choice(OTHER_UNITS)
    noise = rng.randbytes(rng.randrange(0, 24))
    pdu = malformed_pdu(rng.choice(CODES), rng.choice(KINDS), noise, rng.randrange(1 << 16))
    return unit, pdu


def _store() -> MemoryStore:
    """Every table, files, FIFOs and identification objects: every code has data."""
    return MemoryStore(
        coils=[Block(0x13, 19, [1, 0, 1, 1] * 4 + [1, 1, 0]), Block(0xAC, 1)],
        discrete_inputs=Block(0xC4, 22),
        holding_registers=[Block(0, 20, list(range(20))), Block(0x6B, 3, [1, 2, 3])],
        input_registers={0x08: [0x000A]},
        fifo_queues={0x04DE: [0x01B8, 0x1284]},
        files={4: 16, 7: 16, 9: 16},
        device_identification={0: "aiortu", 1: "FUZZ", 2: "1.0", 0x80: "x" * 200},
        server_id=ServerId(b"\x01"),
        exception_status=0x6D,
    )


@dataclass
class SlaveUnderTest:
    """A running slave (units :data:`UNIT` and :data:`PROBE_UNIT`) and a raw master."""

    raw: RawMaster
    slave: Slave
    frames: int = 0
    """Frames sent so far."""

    async def exchange(self, unit: int, pdu: bytes) -> list[str]:
        """Send *pdu* to *unit*, then the probe; return what broke the rules (empty: none)."""
        self.frames += 1
        await self.raw.send(encode_frame(unit, pdu))
        await anyio.sleep(0.008)  # the end of a frame of unknown length is silence
        if self.slave.listen_only:
            self.slave.listen_only = False  # diagnostics 04 asked for it: undo
        await self.raw.send_request(PROBE_UNIT, "07")
        # The probe's reply ends what the slave sent; the bytes before it answer *pdu*.
        received = bytearray()
        with anyio.move_on_after(2.0):
            while not received.endswith(_PROBE_REPLY):
                received += await self.raw.endpoint.receive()
        if not received.endswith(_PROBE_REPLY):
            return [f"no answer to the probe after unit {unit}, request {pdu.hex(' ')}"]
        answer = bytes(received[: -len(_PROBE_REPLY)])
        return check_answers(unit, pdu, [answer] if answer else [])


_PROBE_REPLY = encode_frame(PROBE_UNIT, b"\x07\x6d")
"""The probe's reply (read exception status: the store's 0x6D)."""


@asynccontextmanager
async def slave_under_test() -> AsyncIterator[SlaveUnderTest]:
    """A slave on an unpaced virtual line with a raw master at the other end."""
    master_end, slave_end = virtual_pair()
    slave = Slave(
        slave_end, {UNIT: _store(), PROBE_UNIT: _store()}, frame_gap=0.0, frame_silence=0.004
    )
    async with slave:
        await anyio.sleep(0.02)  # the receiver starts by waiting for silence
        yield SlaveUnderTest(RawMaster(master_end), slave)
    await master_end.aclose()


def _readings(unit: int, pdu: bytes) -> list[bytes]:
    """The requests a slave may read in the frame of *pdu*: *pdu*, and the PDU of each
    shorter frame with a good CRC the frame begins with. A frame is complete as soon as
    its length is known and its CRC checks, so a good request followed by its CRC's low
    byte is that request and then a stray byte (the CRC of the longer frame ends in 00)."""
    frame = encode_frame(unit, pdu)
    prefixes = [frame[1 : end - 2] for end in range(4, len(frame)) if crc16(frame[:end]) == 0]
    return [pdu, *prefixes]


def _answers(request: bytes, reply: bytes) -> str:
    """Why *reply* does not answer *request* ("" if it does)."""
    try:
        response = decode_response(reply)
        assert isinstance(response, Response)
        decode_request(request).check_response(response)
    except ModbusError as error:
        return str(error)
    return ""


def check_answers(unit: int, pdu: bytes, answers: list[bytes]) -> list[str]:
    """What is wrong with *answers* to the request *pdu* sent to *unit*: nothing to a
    broadcast or another unit; to :data:`UNIT`, at most one frame, from that unit, that
    is a spec exception for the code or a reply that answers the request."""
    where = f"unit {unit}, request {pdu.hex(' ')}"
    if unit != UNIT:
        return [f"{where}: answered {a.hex(' ')}" for a in answers]
    if len(answers) > 1:
        return [f"{where}: {len(answers)} answers"]
    problems = []
    for answer in answers:
        reply = answer[1:-2]
        if len(answer) < 4 or crc16(answer) != 0:
            problems.append(f"{where}: answer {answer.hex(' ')} is not one good frame")
        elif answer[0] != UNIT or not reply:
            problems.append(f"{where}: answer {answer.hex(' ')} from the wrong unit")
        elif reply[0] == pdu[0] | EXCEPTION_BIT and (
            pdu[0] < EXCEPTION_BIT or reply == bytes((pdu[0], ExceptionCode.ILLEGAL_FUNCTION))
        ):
            # A code >= 0x80 has no exception form of its own: 01 in that byte will do.
            if len(reply) != 2 or reply[1] not in set(ExceptionCode):
                problems.append(f"{where}: exception answer {reply.hex(' ')} is not a spec one")
        elif reply[0] == pdu[0] < EXCEPTION_BIT:
            errors = [_answers(request, reply) for request in _readings(unit, pdu)]
            if all(errors):
                problems.append(f"{where}: reply {reply.hex(' ')} does not answer it: {errors[0]}")
        else:
            problems.append(f"{where}: answer {reply.hex(' ')} has another function code")
    return problems
