"""The MQTT bridge: a fleet on one machine, aiortu's bridge against modbus4mqtt, and the floor
under a poll.

    python benchmarks/bench_bridge.py                       # every section
    python benchmarks/bench_bridge.py --section fleet --seconds 20
    python benchmarks/bench_bridge.py --section modbus4mqtt --modbus4mqtt /tmp/m4m/bin/modbus4mqtt
    python benchmarks/bench_bridge.py --section floor --seconds 15

**fleet**: 8 `aiortu bridge` processes, each on its own virtual line of 10 simulated units of
50 points (every point published every poll, 1 s), into one mosquitto started here; one
subscriber counts what arrives. Reported: points/s delivered, the bridges' CPU and RSS per
1,000 points, the broker's messages/s (its `$SYS` counters), and whether anything was lost
(the bridges' own counts at SIGTERM against what the subscriber got).

**modbus4mqtt**: one meter served over Modbus TCP by this script (40 measurements polled
every second, changing every second; 10 counters and settings in a 60 s poll class, as
profiles describe them), bridged by `aiortu bridge` and by modbus4mqtt (PyPI; run from its own
venv as a separate process, `--modbus4mqtt PATH`), one at a time, interleaved, into the same
broker. Reported: line transactions per published point, bridge CPU per published point, and
the time from a register change to its MQTT message (p50, p99). `--baseline SRC` runs the
aiortu bridge of another source tree as a third, interleaved (`--baseline /work/main/src`).

**floor**: what a 1 s poll of the meter costs before any MQTT (the loop's wake, the master's
read, the poller's `Device.read`): the part of the bridge's CPU no MQTT code can remove.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path
from tempfile import TemporaryDirectory

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import anyio
from benchmarks.benchlib import add_section_argument, cpu_exact, rss_kib, run_sections, table
from tests.bridge.fleet import BridgeProcess, write_config, write_profile
from tests.bridge.mosquitto import Mosquitto, Subscriber, free_port

FAST, SLOW = 40, 10


def _sys_counter(subscriber: Subscriber, name: str) -> int:
    values = subscriber.on(f"$SYS/broker/messages/{name}")
    return int(values[-1]) if values else 0


def fleet(args: argparse.Namespace) -> list[str]:
    bridges_n, units, points = args.bridges, args.units, args.points
    broker = Mosquitto(extra="sys_interval 1\n")
    broker.start()
    with TemporaryDirectory() as tmp:
        folder = Path(tmp)
        profile = write_profile(folder / "fleet.toml", points)
        subscriber = Subscriber(
            broker.port, ["aiortu/#", "$SYS/broker/messages/#"], "bench", persistent=True
        )
        bridges = [
            BridgeProcess.start(
                f"b{n}",
                write_config(
                    folder / f"b{n}.toml",
                    node=f"b{n}",
                    units=units,
                    url=broker.url,
                    profile=profile,
                    keepalive=10,
                ),
            )
            for n in range(bridges_n)
        ]
        try:
            total = bridges_n * units * points
            last = subscriber.last

            def everything_seen() -> bool:
                values = [t for t in last() if t.count("/") == 2 and t.rsplit("/", 1)[1][0] == "p"]
                return len(values) >= total

            subscriber.wait_for(everything_seen, 120)
            time.sleep(2)
            cpu0 = sum(cpu_exact(b.process.pid) for b in bridges)
            got0, received0 = len(subscriber.messages), _sys_counter(subscriber, "received")
            sent0, start = _sys_counter(subscriber, "sent"), time.monotonic()
            time.sleep(args.seconds)
            elapsed = time.monotonic() - start
            cpu = sum(cpu_exact(b.process.pid) for b in bridges) - cpu0
            got = len(subscriber.messages) - got0
            received = _sys_counter(subscriber, "received") - received0
            sent = _sys_counter(subscriber, "sent") - sent0
            rss = sum(rss_kib(b.process.pid) for b in bridges)
            counts = [b.stop() for b in bridges]
            time.sleep(1)
            values = sum(c["values"] for c in counts)
            with subscriber.lock:
                seen = sum(
                    1
                    for m in subscriber.messages
                    if m.topic.startswith("aiortu/b")
                    and m.topic.rsplit("/", 1)[1][:1] == "p"
                    and not m.retain
                )
        finally:
            for bridge in bridges:
                if bridge.process.poll() is None:
                    bridge.kill()
            subscriber.close()
            broker.close()
    lost = max(0, values - seen)
    rows = [
        [
            f"{bridges_n} x {units} units x {points} points",
            f"{got / elapsed:,.0f}",
            f"{cpu / elapsed / total * 1000 * 1000:.1f}",
            f"{rss / total * 1000 / 1024:.1f}",
            f"{(received + sent) / elapsed:,.0f}",
            f"{sum(c['dropped'] for c in counts)}",
            f"{lost}",
        ]
    ]
    return [
        f"## Fleet ({args.seconds:.0f} s measured, every point published every 1 s poll)",
        "",
        table(
            [
                "fleet",
                "points/s delivered",
                "bridge CPU ms/s per 1,000 points",
                "bridge RSS MiB per 1,000 points",
                "broker MQTT messages/s ($SYS received + sent)",
                "dropped",
                "lost",
            ],
            rows,
        ),
        f"(the subscriber counted {seen:,} value messages; the bridges made {values:,})",
    ]


def _meter_profile(path: Path) -> Path:
    """40 input-register measurements (1 s) and 10 counters and settings (60 s)."""
    parts = ['[device]\nmanufacturer = "aiortu"\nmodel = "bench-meter"\n', "[poll]\nslow = 60.0\n"]
    for n in range(FAST):
        parts.append(
            f'[[point]]\nname = "f{n:02}"\ntable = "input_registers"\naddress = {n}\n'
            f'type = "u16"\nvalue = {n}\n'
        )
    for n in range(SLOW // 2):
        address = 300 + 2 * n
        parts.append(
            f'[[point]]\nname = "e{n}"\ntable = "input_registers"\n'
            f'address = {address}\ntype = "u32"\npoll = "slow"\nvalue = 1000\n'
        )
    for n in range(SLOW // 2):
        parts.append(
            f'[[point]]\nname = "s{n}"\naddress = {1000 + n}\ntype = "u16"\n'
            f'poll = "slow"\naccess = "rw"\nvalue = 5\n'
        )
    path.write_text("\n".join(parts))
    return path


def _modbus4mqtt_config(path: Path, port: int) -> Path:
    regs = [
        f"  - pub_topic: meter/f{n:02}\n    address: {n}\n    table: input\n" for n in range(FAST)
    ]
    regs += [
        f"  - pub_topic: meter/e{n}\n    address: {300 + 2 * n}\n    table: input\n"
        "    type: uint32\n"
        for n in range(SLOW // 2)
    ]
    regs += [
        f"  - pub_topic: meter/s{n}\n    address: {1000 + n}\n    table: holding\n"
        for n in range(SLOW // 2)
    ]
    path.write_text(
        f"ip: 127.0.0.1\nport: {port}\nupdate_rate: 1\ndevice_address: 1\n"
        f"address_offset: 0\nregisters:\n{''.join(regs)}"
    )
    return path


class _Meter:
    """The meter, served over Modbus TCP in a thread; its measurements change every second;
    `requests` counts the transactions; `changed[value]` is when f00 took `value`."""

    def __init__(self, profile: Path) -> None:
        from aiortu.core.model import load_profile
        from aiortu.slave import ModbusTcpServer, ProfileStore

        self.store = ProfileStore(load_profile(profile))
        self.requests = 0
        self.changed: dict[int, float] = {}
        self.port = free_port()
        self.server = ModbusTcpServer({1: self.store}, trace=self._trace)
        self._stop = threading.Event()
        self.thread = threading.Thread(target=anyio.run, args=(self._serve,), daemon=True)
        self.thread.start()

    def _trace(self, direction: str, adu: bytes) -> None:
        if direction == "received":
            self.requests += 1

    async def _serve(self) -> None:
        listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=self.port)
        async with anyio.create_task_group() as tasks:
            tasks.start_soon(self.server.serve, listener)
            value = 100
            while not self._stop.is_set():
                await anyio.sleep(1.0)
                value += 1
                for n in range(FAST):
                    self.store.set_value(f"f{n:02}", (value + n) % 65536)
                self.changed[value % 65536] = time.monotonic()
            tasks.cancel_scope.cancel()

    def close(self) -> None:
        self._stop.set()
        self.thread.join(5)


def _run_one(
    name: str,
    command: list[str],
    meter: _Meter,
    subscriber: Subscriber,
    prefix: str,
    seconds: float,
    env: dict[str, str] | None = None,
) -> dict[str, float]:
    seen = len(subscriber.on(f"{prefix}/meter/f00"))
    process = subprocess.Popen(
        command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env
    )
    try:
        # Two values of this run (not of an earlier one): its start-up is over.
        subscriber.wait_for(lambda: len(subscriber.on(f"{prefix}/meter/f00")) >= seen + 2, 30)
        time.sleep(1.0)
        cpu0, requests0 = cpu_exact(process.pid), meter.requests
        with subscriber.lock:
            first = len(subscriber.messages)
        time.sleep(seconds)
        cpu, requests = cpu_exact(process.pid) - cpu0, meter.requests - requests0
        with subscriber.lock:
            window = subscriber.messages[first:]
    finally:
        process.terminate()
        process.wait(10)
    mine = [m for m in window if m.topic.startswith(f"{prefix}/meter/")]
    latencies = [
        m.at - meter.changed[int(float(m.payload))]
        for m in mine
        if m.topic.endswith("/f00") and int(float(m.payload)) in meter.changed
    ]
    published = len(mine)
    return {
        "transactions per point": requests / published,
        "CPU us per point": cpu / published * 1e6,
        "p50 ms": statistics.median(latencies) * 1000,
        "p99 ms": statistics.quantiles(latencies, n=100)[98] * 1000
        if len(latencies) > 2
        else max(latencies) * 1000,
        "points/s": published / seconds,
    }


def versus_modbus4mqtt(args: argparse.Namespace) -> list[str]:
    broker = Mosquitto()
    broker.start()
    results: dict[str, list[dict[str, float]]] = {"aiortu bridge": [], "modbus4mqtt": []}
    baseline = f"aiortu bridge ({args.baseline})" if args.baseline else None
    if baseline is not None:
        results[baseline] = []
    with TemporaryDirectory() as tmp:
        folder = Path(tmp)
        meter = _Meter(_meter_profile(folder / "meter.toml"))
        (folder / "bridge.toml").write_text(
            f'[broker]\nurl = "{broker.url}"\n[topics]\nlayout = "plain"\nprefix = "aiortu"\n'
            f"qos = {args.qos}\n"
            f'[[line]]\nport = "tcp://127.0.0.1:{meter.port}"\n'
            f'[[line.device]]\nname = "meter"\nunit = 1\nprofile = "{folder / "meter.toml"}"\n'
        )
        m4m = _modbus4mqtt_config(folder / "meter.yaml", meter.port)
        commands = {
            "aiortu bridge": [
                sys.executable,
                "-m",
                "aiortu",
                "bridge",
                "--config",
                str(folder / "bridge.toml"),
            ],
            "modbus4mqtt": [
                args.modbus4mqtt,
                "--hostname",
                "127.0.0.1",
                "--port",
                str(broker.port),
                "--config",
                str(m4m),
                "--mqtt_topic_prefix",
                "m4m",
            ],
        }
        prefixes = {"aiortu bridge": "aiortu", "modbus4mqtt": "m4m"}
        envs: dict[str, dict[str, str] | None] = {"aiortu bridge": None, "modbus4mqtt": None}
        if baseline is not None:
            commands[baseline] = commands["aiortu bridge"]
            prefixes[baseline] = "aiortu"
            envs[baseline] = {**os.environ, "PYTHONPATH": args.baseline}
        subscriber = Subscriber(broker.port, ["aiortu/#", "m4m/#"], "bench")
        try:
            for _ in range(args.rounds):
                for name, command in commands.items():
                    results[name].append(
                        _run_one(
                            name,
                            command,
                            meter,
                            subscriber,
                            prefixes[name],
                            args.seconds,
                            envs[name],
                        )
                    )
        finally:
            subscriber.close()
            meter.close()
            broker.close()
    keys = ["transactions per point", "CPU us per point", "p50 ms", "p99 ms", "points/s"]
    medians = {
        n: {k: statistics.median(r[k] for r in runs) for k in keys} for n, runs in results.items()
    }
    rows = [
        [
            name,
            *(
                f"{medians[name][k]:.3f}"
                if k == "transactions per point"
                else f"{medians[name][k]:.1f}"
                if k == "CPU us per point"
                else f"{medians[name][k]:.0f}"
                for k in keys
            ),
        ]
        for name in results
    ]
    ratio = {k: medians["aiortu bridge"][k] / medians["modbus4mqtt"][k] for k in keys[:2]}
    cpu = "CPU us per point"
    others = [
        f"{name} / modbus4mqtt: CPU per published point "
        f"{medians[name][cpu] / medians['modbus4mqtt'][cpu]:.3f}x"
        for name in results
        if name not in ("aiortu bridge", "modbus4mqtt")
    ]
    return [
        f"## Against modbus4mqtt ({args.rounds} interleaved rounds of {args.seconds:.0f} s each; "
        f"medians; 1 s poll, values changing every second; aiortu at QoS {args.qos}, "
        "modbus4mqtt at QoS 0)",
        "",
        table(["bridge", *keys], rows),
        "",
        f"aiortu / modbus4mqtt: line transactions per published point "
        f"{ratio['transactions per point']:.2f}x, CPU per published point "
        f"{ratio['CPU us per point']:.3f}x",
        *others,
    ]


def floor(args: argparse.Namespace) -> list[str]:
    """What a 1 s poll costs before any MQTT: the event loop woken once a second, then with
    one read of the meter's 40 measurements by the master, then by `Device.read` (what the
    bridge's poller does). CPU of the polling thread (`time.thread_time`), the meter served by
    another thread; alone on the machine, not interleaved (each a floor under the bridge)."""
    from aiortu.core.model import load_profile
    from aiortu.master import Device, open_master

    rows: list[list[str]] = []
    with TemporaryDirectory() as tmp:
        meter = _Meter(_meter_profile(Path(tmp) / "meter.toml"))
        profile = load_profile(Path(tmp) / "meter.toml")

        async def main() -> None:
            await anyio.sleep(0.5)  # the meter's listener
            url = f"tcp://127.0.0.1:{meter.port}"
            async with open_master(url, fail_fast_offline=True) as master:
                device = Device(master, 1, profile)
                polls = {
                    "the loop woken once a second": None,
                    "+ master.read_input_registers(1, 0, 40)": (
                        lambda: master.read_input_registers(1, 0, 40)
                    ),
                    "+ Device.read (the poller's read)": lambda: device.read("normal"),
                }
                for name, poll in polls.items():
                    await device.read("normal")
                    start, cycles = time.thread_time(), max(3, round(args.seconds))
                    for _ in range(cycles):
                        if poll is not None:
                            await poll()
                        await anyio.sleep(1.0)
                    cpu = (time.thread_time() - start) / cycles
                    rows.append([name, f"{cpu * 1e3:.2f}", f"{cpu / FAST * 1e6:.1f}"])

        try:
            anyio.run(main)
        finally:
            meter.close()
    return [
        f"## The floor under a 1 s poll ({max(3, round(args.seconds))} polls each)",
        "",
        table(["each second", "CPU ms/s", f"us per point at {FAST} points/s"], rows),
    ]


SECTIONS = {"fleet": fleet, "modbus4mqtt": versus_modbus4mqtt, "floor": floor}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_section_argument(parser, SECTIONS)
    parser.add_argument("--seconds", type=float, default=20.0, help="measured time per run")
    parser.add_argument("--rounds", type=int, default=3, help="interleaved rounds (modbus4mqtt)")
    parser.add_argument(
        "--qos",
        type=int,
        default=1,
        choices=(0, 1),
        help="the aiortu bridge's QoS (modbus4mqtt publishes at 0)",
    )
    parser.add_argument("--bridges", type=int, default=8)
    parser.add_argument("--units", type=int, default=10)
    parser.add_argument("--points", type=int, default=50)
    parser.add_argument(
        "--modbus4mqtt", default="modbus4mqtt", help="the modbus4mqtt command (from its own venv)"
    )
    parser.add_argument(
        "--baseline",
        metavar="SRC",
        help="also run the aiortu bridge of this source tree (PYTHONPATH), interleaved",
    )
    run_sections(parser.parse_args(), SECTIONS)


if __name__ == "__main__":
    main()
