"""Diagnostics (08), the comm event counter and log (0B, 0C), report server ID (11), file
records (14, 15) and device identification (2B/0E) on the slave, byte for byte."""

from __future__ import annotations

import anyio
import pytest

from aiortu.core.machines import receive_event, send_event
from aiortu.core.rtu import encode_frame
from aiortu.slave import MemoryStore, ServerId, Table

from .helpers import UNIT, example_store, slave_line


def serial_store() -> MemoryStore:
    return MemoryStore(
        holding_registers={0: 10},
        files={4: [0x06AF, 0x04BE, 0x100D], 3: [0, 0, 0, 0, 0, 0, 0, 0, 0, 0x0DFE, 0x0020]},
        device_identification={0: "aiortu", 1: "SIM", 2: "1.0", 4: "meter", 0x80: "x"},
        server_id=ServerId(b"\x11\x22", True, b"ab"),
    )


async def test_08_00_echoes_the_query_data() -> None:
    async with slave_line() as (master, _):
        assert await master.request(UNIT, "08 00 00 A5 37") == "08 00 00 A5 37"


async def test_08_counters_after_scripted_traffic() -> None:
    store = example_store()
    async with slave_line({UNIT: store, 5: MemoryStore()}) as (master, slave):
        await master.request(UNIT, "03 00 6B 00 03")  # 1 normal
        await master.request(UNIT, "03 00 00 00 7E")  # 2 exception 03
        await master.request(UNIT, "0D")  # 3 exception 01
        await master.send_request(0, "06 00 01 00 05")  # 4 broadcast: no response
        await master.send(encode_frame(UNIT, bytes.fromhex("03 00 6B 00 03"))[:-1] + b"\x00")
        # Silence after the bad frame: glued to it, another unit's request would be part
        # of the garbage (a slave searches garbage for its own requests only) and not count.
        await anyio.sleep(0.05)
        await master.send_request(99, "03 00 00 00 01")  # 5 another unit's request
        await master.assert_silent_then_alive()  # 6 (07)
        slave.machine.diagnostic_register = 0x1234
        # Each counter read is itself a message: bus and server counts include it.
        assert await master.request(UNIT, "08 00 0B 00 00") == "08 00 0B 00 07"
        assert await master.request(UNIT, "08 00 0C 00 00") == "08 00 0C 00 01"
        assert await master.request(UNIT, "08 00 0D 00 00") == "08 00 0D 00 02"
        assert await master.request(UNIT, "08 00 0E 00 00") == "08 00 0E 00 09"
        assert await master.request(UNIT, "08 00 0F 00 00") == "08 00 0F 00 01"
        assert await master.request(UNIT, "08 00 10 00 00") == "08 00 10 00 00"
        assert await master.request(UNIT, "08 00 11 00 00") == "08 00 11 00 00"
        assert await master.request(UNIT, "08 00 12 00 00") == "08 00 12 00 00"
        assert await master.request(UNIT, "08 00 02 00 00") == "08 00 02 12 34"
        assert await master.request(UNIT, "08 00 0A 00 00") == "08 00 0A 00 00"
        assert await master.request(UNIT, "08 00 0B 00 00") == "08 00 0B 00 01"
        assert await master.request(UNIT, "08 00 02 00 00") == "08 00 02 00 00"
    assert store.get(Table.HOLDING_REGISTERS, 1) == [5]


async def test_08_overrun_counter_and_clear() -> None:
    async with slave_line() as (master, slave):
        slave.counters.bus_character_overrun_count = 3
        assert await master.request(UNIT, "08 00 12 00 00") == "08 00 12 00 03"
        assert await master.request(UNIT, "08 00 14 00 00") == "08 00 14 00 00"
        assert await master.request(UNIT, "08 00 12 00 00") == "08 00 12 00 00"


async def test_08_03_stores_the_ascii_delimiter() -> None:
    async with slave_line() as (master, slave):
        assert await master.request(UNIT, "08 00 03 3A 00") == "08 00 03 3A 00"
    assert slave.machine.ascii_delimiter == 0x3A


async def test_08_04_listen_only_then_01_restart() -> None:
    store = example_store()
    async with slave_line({UNIT: store}) as (master, slave):
        await master.send_request(UNIT, "08 00 04 00 00")
        assert await master.receive_frame(0.05) is None
        assert slave.listen_only
        await master.send_request(UNIT, "06 00 01 00 09")  # monitored, not executed
        await master.send_request(UNIT, "03 00 6B 00 01")
        assert await master.receive_frame(0.05) is None
        # Restart leaves listen-only mode, but the request itself is not answered.
        await master.send_request(UNIT, "08 00 01 00 00")
        assert await master.receive_frame(0.05) is None
        assert not slave.listen_only
        assert await master.request(UNIT, "03 00 6B 00 01") == "03 02 AE 41"
        # Now a restart is answered (echo), and clears the counters.
        assert await master.request(UNIT, "08 00 01 FF 00") == "08 00 01 FF 00"
        assert await master.request(UNIT, "08 00 0E 00 00") == "08 00 0E 00 01"
        log = await master.request(UNIT, "0C")
    assert store.get(Table.HOLDING_REGISTERS, 1) == [0]
    # After a restart with FF00 the log holds the restart, then what followed.
    expected = bytes((receive_event(), send_event(), receive_event(), 0x00))
    assert log == "0C 0A 00 00 00 01 00 02 " + expected.hex(" ").upper()


async def test_0b_counts_successful_completions_only() -> None:
    async with slave_line() as (master, _):
        assert await master.request(UNIT, "0B") == "0B 00 00 00 00"
        await master.request(UNIT, "03 00 6B 00 01")
        await master.request(UNIT, "03 00 00 00 7E")  # an exception: not counted
        await master.send_request(0, "06 00 01 00 05")  # a broadcast completes
        await master.assert_silent_then_alive()  # 07: counted
        assert await master.request(UNIT, "0B") == "0B 00 00 00 03"
        assert await master.request(UNIT, "0C") != ""
        assert await master.request(UNIT, "0B") == "0B 00 00 00 03"


async def test_0c_event_log_encodings_newest_first() -> None:
    async with slave_line() as (master, _):
        await master.request(UNIT, "03 00 6B 00 01")
        await master.request(UNIT, "03 00 00 00 7E")  # exception 03
        await master.request(UNIT, "01 00 12 00 02")  # exception 02
        await master.send_request(0, "06 00 01 00 05")
        await master.send_request(UNIT, "08 00 04 00 00")
        await master.send_request(UNIT, "08 00 01 00 00")
        await master.assert_silent_then_alive()
        reply = bytes.fromhex(await master.request(UNIT, "0C"))
    events = reply[8:]
    assert reply[1] == 6 + len(events)
    # Newest first: 0C received; 07 sent, received; restart (0x00); ...
    assert events[:4] == bytes((0x80, 0x40, 0x80, 0x00))
    # The restart request arrived and was finished in listen-only mode (bit 5), after
    # the 0x04 entry of force listen-only mode.
    assert events[4:9] == bytes((0x60, 0xA0, 0x04, 0x80, 0x40))
    assert events[9] == 0xC0  # the broadcast received
    assert events[10:12] == bytes((0x41, 0x80))  # exception 02 sent (read exception)
    assert events[12:14] == bytes((0x41, 0x80))  # exception 03 sent
    assert events[14:16] == bytes((0x40, 0x80))
    # The restart cleared the counters: since then 07 completed; 07 and 0C were seen.
    assert reply[2:8] == bytes.fromhex("00 00 00 01 00 02")


async def test_0c_log_keeps_64_events() -> None:
    async with slave_line() as (master, _):
        for _ in range(40):
            await master.request(UNIT, "07")
        reply = bytes.fromhex(await master.request(UNIT, "0C"))
    assert reply[1] == 6 + 64
    assert len(reply) == 8 + 64


async def test_11_report_server_id() -> None:
    async with slave_line({UNIT: serial_store(), 5: MemoryStore()}) as (master, _):
        assert await master.request(UNIT, "11") == "11 05 11 22 FF 61 62"
        # A store without a server id answers with the unit address, running.
        assert await master.request(5, "11") == "11 02 05 FF"


async def test_14_read_file_record_spec_example() -> None:
    async with slave_line({UNIT: serial_store()}) as (master, _):
        reply = await master.request(UNIT, "14 0E 06 00 04 00 01 00 02 06 00 03 00 09 00 02")
    assert reply == "14 0C 05 06 04 BE 10 0D 05 06 0D FE 00 20"


async def test_15_write_file_record_spec_example() -> None:
    store = serial_store()
    request = "15 0D 06 00 04 00 07 00 03 06 AF 04 BE 10 0D"
    store.files[4] = [0] * 10
    async with slave_line({UNIT: store}) as (master, _):
        assert await master.request(UNIT, request) == request
        assert await master.request(UNIT, "14 07 06 00 04 00 07 00 03") == (
            "14 08 07 06 06 AF 04 BE 10 0D"
        )
    assert store.files[4][7:10] == [0x06AF, 0x04BE, 0x100D]


@pytest.mark.parametrize(
    ("request_pdu", "reply_pdu"),
    [
        pytest.param("14 07 06 00 09 00 00 00 01", "94 02", id="14-no-such-file"),
        pytest.param("14 07 06 00 04 00 02 00 02", "94 02", id="14-past-the-file"),
        pytest.param("14 07 07 00 04 00 00 00 01", "94 02", id="14-reference-type"),
        pytest.param("14 07 06 00 04 27 10 00 01", "94 02", id="14-record-10000"),
        pytest.param("14 07 06 00 04 00 00 00 00", "94 03", id="14-length-0"),
        pytest.param("14 08 06 00 04 00 00 00 01", "94 03", id="14-byte-count"),
        pytest.param("15 09 06 00 09 00 00 00 01 00 01", "95 02", id="15-no-such-file"),
        pytest.param("15 09 06 00 04 00 03 00 01 00 01", "95 02", id="15-past-the-file"),
        pytest.param("15 0A 06 00 04 00 00 00 01 00 01", "95 03", id="15-byte-count"),
        pytest.param("2B 0E 05 00", "AB 03", id="2B-read-code-5"),
        pytest.param("2B 0E 00 00", "AB 03", id="2B-read-code-0"),
        pytest.param("2B 0E 04 05", "AB 02", id="2B-individual-unknown"),
        pytest.param("2B 0D 01 00", "AB 01", id="2B-other-mei-type"),
        pytest.param("2B 0E 01", "AB 03", id="2B-short"),
        pytest.param("0B 00", "8B 03", id="0B-length"),
        pytest.param("0C 00", "8C 03", id="0C-length"),
        pytest.param("11 00", "91 03", id="11-length"),
        pytest.param("08 00 01 12 34", "88 03", id="08-01-bad-data"),
        pytest.param("08 00 0B 00 01", "88 03", id="08-0B-data-not-0"),
        pytest.param("08 00 00 01", "88 03", id="08-00-odd-data"),
        pytest.param("08 00 16 00 00", "88 01", id="08-sub-16"),
        pytest.param("08 12 34 00 00", "88 01", id="08-sub-1234"),
    ],
)
async def test_exceptions_of_the_serial_line_codes(request_pdu: str, reply_pdu: str) -> None:
    store = serial_store()
    before = list(store.files[4])
    async with slave_line({UNIT: store}) as (master, slave):
        assert await master.request(UNIT, request_pdu) == reply_pdu
    assert store.files[4] == before
    assert slave.counters.bus_exception_error_count == 1


async def test_store_without_files_or_identification_gives_01() -> None:
    async with slave_line({UNIT: MemoryStore()}) as (master, _):
        assert await master.request(UNIT, "14 07 06 00 04 00 00 00 01") == "94 02"
        assert await master.request(UNIT, "2B 0E 01 00") == "AB 01"


async def test_2b_basic_regular_extended_and_individual() -> None:
    async with slave_line({UNIT: serial_store()}) as (master, _):
        basic = await master.request(UNIT, "2B 0E 01 00")
        regular = await master.request(UNIT, "2B 0E 02 00")
        extended = await master.request(UNIT, "2B 0E 03 00")
        single = await master.request(UNIT, "2B 0E 04 04")
        restart = await master.request(UNIT, "2B 0E 01 05")  # unknown id: from the start
    objects = "00 06 61 69 6F 72 74 75 01 03 53 49 4D 02 03 31 2E 30"
    assert basic == "2B 0E 01 83 00 00 03 " + objects.upper()
    assert regular == "2B 0E 02 83 00 00 04 " + objects.upper() + " 04 05 6D 65 74 65 72"
    assert extended.startswith("2B 0E 03 83 00 00 05 ")
    assert extended.endswith("80 01 78")
    assert single == "2B 0E 04 83 00 00 01 04 05 6D 65 74 65 72"
    assert restart == basic


async def test_2b_streams_with_more_follows_when_objects_do_not_fit() -> None:
    objects = {0: "v", 1: "p", 2: "r"} | {0x80 + index: "x" * 100 for index in range(5)}
    store = MemoryStore(device_identification=objects)
    async with slave_line({UNIT: store}) as (master, _):
        first = bytes.fromhex(await master.request(UNIT, "2B 0E 03 00"))
        second = bytes.fromhex(await master.request(UNIT, "2B 0E 03 " + f"{first[5]:02X}"))
        third = bytes.fromhex(await master.request(UNIT, "2B 0E 03 " + f"{second[5]:02X}"))
    assert first[3:7] == bytes((0x83, 0xFF, 0x82, 5))  # 3 basic + 2 private objects
    assert second[3:7] == bytes((0x83, 0xFF, 0x84, 2))
    assert third[3:7] == bytes((0x83, 0x00, 0x00, 1))
    assert len(first) <= 253
