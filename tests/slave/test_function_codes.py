"""Every built-in function code of the slave, byte for byte, and the spec's exceptions."""

from __future__ import annotations

import pytest

from aiortu.slave import MemoryStore, Table

from .helpers import UNIT, example_store, slave_line

# (request PDU, reply PDU), from the examples of the application protocol spec.
SPEC_EXAMPLES = [
    pytest.param("01 00 13 00 13", "01 03 CD 6B 05", id="01-read-coils"),
    pytest.param("02 00 C4 00 16", "02 03 AC DB 35", id="02-read-discrete-inputs"),
    pytest.param("03 00 6B 00 03", "03 06 AE 41 56 52 43 40", id="03-read-holding-registers"),
    pytest.param("04 00 08 00 01", "04 02 00 0A", id="04-read-input-registers"),
    pytest.param("05 00 AC FF 00", "05 00 AC FF 00", id="05-write-single-coil"),
    pytest.param("06 00 01 00 03", "06 00 01 00 03", id="06-write-single-register"),
    pytest.param("07", "07 6D", id="07-read-exception-status"),
    pytest.param("0F 00 13 00 0A 02 CD 01", "0F 00 13 00 0A", id="0F-write-multiple-coils"),
    pytest.param("10 00 01 00 02 04 00 0A 01 02", "10 00 01 00 02", id="10-write-registers"),
    pytest.param(
        "17 00 03 00 06 00 0E 00 03 06 00 FF 00 FF 00 FF",
        "17 0C 00 FE 0A CD 00 01 00 03 00 0D 00 FF",
        id="17-read-write-registers",
    ),
    pytest.param("18 04 DE", "18 00 06 00 02 01 B8 12 84", id="18-read-fifo-queue"),
]


@pytest.mark.parametrize(("request_pdu", "reply_pdu"), SPEC_EXAMPLES)
async def test_spec_example_replies_byte_exact(request_pdu: str, reply_pdu: str) -> None:
    async with slave_line() as (master, _):
        assert await master.request(UNIT, request_pdu) == reply_pdu


async def test_03_reply_frame_is_the_notes_example() -> None:
    async with slave_line() as (master, _):
        await master.send_request(UNIT, "03 00 6B 00 03")
        frame = await master.receive_frame()
    assert frame == bytes.fromhex("11 03 06 AE 41 56 52 43 40 49 AD")


async def test_writes_reach_the_store() -> None:
    store = example_store()
    async with slave_line({UNIT: store}) as (master, _):
        await master.request(UNIT, "05 00 AC FF 00")
        assert store.get(Table.COILS, 0xAC) == [True]
        await master.request(UNIT, "05 00 AC 00 00")
        assert store.get(Table.COILS, 0xAC) == [False]
        await master.request(UNIT, "06 00 01 00 03")
        await master.request(UNIT, "10 00 07 00 02 04 00 0A 01 02")
        assert store.get(Table.HOLDING_REGISTERS, 1) == [3]
        assert store.get(Table.HOLDING_REGISTERS, 7, 2) == [0x000A, 0x0102]
        await master.request(UNIT, "0F 00 13 00 0A 02 CD 01")
        assert store.get(Table.COILS, 0x13, 10) == [1, 0, 1, 1, 0, 0, 1, 1, 1, 0]
        # 17 writes before it reads: the read sees the values just written.
        reply = await master.request(UNIT, "17 00 0E 00 02 00 0E 00 02 04 12 34 56 78")
        assert reply == "17 04 12 34 56 78"


async def test_16_mask_write_register_spec_example() -> None:
    store = MemoryStore(holding_registers={0x04: [0x12]})
    async with slave_line({UNIT: store}) as (master, _):
        assert await master.request(UNIT, "16 00 04 00 F2 00 25") == "16 00 04 00 F2 00 25"
    assert store.get(Table.HOLDING_REGISTERS, 0x04) == [0x17]


async def test_07_without_an_exception_status_answers_zero() -> None:
    class Minimal:
        def read(self, table: Table, address: int, count: int) -> list[int]:
            return [0] * count

        def write(self, table: Table, address: int, values: object) -> None:
            pass

    async with slave_line({UNIT: Minimal()}) as (master, _):
        assert await master.request(UNIT, "07") == "07 00"
        assert await master.request(UNIT, "18 00 00") == "98 02"


EXCEPTIONS = [
    # Unsupported function codes, whatever their data: 01.
    pytest.param("0D", "8D 01", id="0D-unsupported"),
    pytest.param("08 00 21 00 00", "88 01", id="08-unknown-sub-function"),
    pytest.param("41 01 02", "C1 01", id="user-code-without-handler"),
    pytest.param("00", "80 01", id="code-0"),
    # Quantity 0 and max + 1: 03.
    pytest.param("01 00 13 00 00", "81 03", id="01-count-0"),
    pytest.param("01 00 13 07 D1", "81 03", id="01-count-2001"),
    pytest.param("02 00 C4 00 00", "82 03", id="02-count-0"),
    pytest.param("02 00 C4 07 D1", "82 03", id="02-count-2001"),
    pytest.param("03 00 6B 00 00", "83 03", id="03-count-0"),
    pytest.param("03 00 6B 00 7E", "83 03", id="03-count-126"),
    pytest.param("04 00 08 00 00", "84 03", id="04-count-0"),
    pytest.param("04 00 08 00 7E", "84 03", id="04-count-126"),
    pytest.param("0F 00 13 00 00 00", "8F 03", id="0F-count-0"),
    pytest.param("0F 00 13 07 B1 F7" + " 00" * 247, "8F 03", id="0F-count-1969"),
    pytest.param("10 00 01 00 00 00", "90 03", id="10-count-0"),
    # 124 registers cannot fit in a frame; the count is checked before the data.
    pytest.param("10 00 01 00 7C F8" + " 00" * 240, "90 03", id="10-count-124"),
    pytest.param("17 00 03 00 00 00 0E 00 01 02 00 01", "97 03", id="17-read-count-0"),
    pytest.param("17 00 03 00 7E 00 0E 00 01 02 00 01", "97 03", id="17-read-count-126"),
    pytest.param("17 00 03 00 01 00 0E 00 00 00", "97 03", id="17-write-count-0"),
    pytest.param("17 00 03 00 01 00 0E 00 7A F4" + " 00" * 240, "97 03", id="17-write-122"),
    # A coil value other than 0xFF00 / 0x0000: 03.
    pytest.param("05 00 AC 12 34", "85 03", id="05-coil-value"),
    pytest.param("05 00 AC 00 FF", "85 03", id="05-coil-value-swapped"),
    # A byte count that does not match the quantity: 03.
    pytest.param("0F 00 13 00 0A 01 CD", "8F 03", id="0F-byte-count"),
    pytest.param("10 00 01 00 02 02 00 0A", "90 03", id="10-byte-count"),
    pytest.param("17 00 03 00 01 00 0E 00 02 02 00 01", "97 03", id="17-byte-count"),
    # A PDU of the wrong length: 03.
    pytest.param("03 00 6B", "83 03", id="03-short"),
    # A range that starts outside the map: 02.
    pytest.param("01 00 12 00 02", "81 02", id="01-starts-outside"),
    pytest.param("02 00 C3 00 01", "82 02", id="02-starts-outside"),
    pytest.param("03 00 6A 00 01", "83 02", id="03-starts-outside"),
    pytest.param("04 00 07 00 01", "84 02", id="04-starts-outside"),
    pytest.param("05 00 AD FF 00", "85 02", id="05-outside"),
    pytest.param("06 00 20 00 01", "86 02", id="06-outside"),
    pytest.param("0F 00 12 00 01 01 01", "8F 02", id="0F-starts-outside"),
    pytest.param("10 00 14 00 01 02 00 01", "90 02", id="10-starts-outside"),
    pytest.param("16 00 14 FF FF 00 00", "96 02", id="16-outside"),
    pytest.param("17 00 20 00 01 00 00 00 01 02 00 01", "97 02", id="17-read-outside"),
    pytest.param("17 00 00 00 01 00 20 00 01 02 00 01", "97 02", id="17-write-outside"),
    pytest.param("18 00 01", "98 02", id="18-no-such-fifo"),
    # A range that ends outside the map: 02.
    pytest.param("01 00 13 00 14", "81 02", id="01-ends-outside"),
    pytest.param("02 00 C4 00 17", "82 02", id="02-ends-outside"),
    pytest.param("03 00 6B 00 04", "83 02", id="03-ends-outside"),
    pytest.param("04 00 08 00 02", "84 02", id="04-ends-outside"),
    pytest.param("0F 00 25 00 02 01 03", "8F 02", id="0F-ends-outside"),
    pytest.param("10 00 13 00 02 04 00 01 00 02", "90 02", id="10-ends-outside"),
    pytest.param("17 00 13 00 02 00 00 00 01 02 00 01", "97 02", id="17-read-ends-outside"),
    # Past address 65535: 02 from the decoder.
    pytest.param("03 FF FF 00 02", "83 02", id="03-past-65535"),
    # Both quantity and address wrong: the quantity comes first, 03.
    pytest.param("03 FF FF 00 7E", "83 03", id="03-order-quantity-first"),
    pytest.param("03 FF FF 00 00", "83 03", id="03-order-count-0-unmapped"),
    pytest.param("01 FF F0 07 D1", "81 03", id="01-order"),
]


@pytest.mark.parametrize(("request_pdu", "reply_pdu"), EXCEPTIONS)
async def test_spec_exceptions(request_pdu: str, reply_pdu: str) -> None:
    async with slave_line() as (master, slave):
        assert await master.request(UNIT, request_pdu) == reply_pdu
    assert slave.counters.bus_exception_error_count == 1


async def test_failed_writes_change_nothing() -> None:
    store = example_store()
    before = store.get(Table.HOLDING_REGISTERS, 0, 20)
    async with slave_line({UNIT: store}) as (master, _):
        # The write part is mapped, the read part is not: 02 and nothing written.
        assert await master.request(UNIT, "17 00 20 00 01 00 00 00 01 02 12 34") == "97 02"
        assert await master.request(UNIT, "10 00 13 00 02 04 00 01 00 02") == "90 02"
    assert store.get(Table.HOLDING_REGISTERS, 0, 20) == before


async def test_read_only_range_gives_02_and_is_kept() -> None:
    store = MemoryStore(
        holding_registers={0: [1, 2, 3, 4]}, read_only={Table.HOLDING_REGISTERS: [range(2, 4)]}
    )
    async with slave_line({UNIT: store}) as (master, _):
        assert await master.request(UNIT, "06 00 02 00 09") == "86 02"
        assert await master.request(UNIT, "10 00 01 00 02 04 00 09 00 09") == "90 02"
        assert await master.request(UNIT, "06 00 01 00 09") == "06 00 01 00 09"
        assert await master.request(UNIT, "03 00 00 00 04") == "03 08 00 01 00 09 00 03 00 04"


async def test_fifo_with_more_than_31_values_gives_03() -> None:
    store = MemoryStore(fifo_queues={5: range(32)})
    async with slave_line({UNIT: store}) as (master, _):
        assert await master.request(UNIT, "18 00 05") == "98 03"
        store.fifo_queues[5].popleft()
        assert (await master.request(UNIT, "18 00 05")).startswith("18 00 40 00 1F 00 01")


async def test_aliased_tables_share_values() -> None:
    store = MemoryStore(holding_registers={0: 4}, input_registers=Table.HOLDING_REGISTERS)
    async with slave_line({UNIT: store}) as (master, _):
        await master.request(UNIT, "06 00 03 AB CD")
        assert await master.request(UNIT, "04 00 03 00 01") == "04 02 AB CD"
