"""Helpers shared by the benchmark scripts: the machine header, socat pty pairs, child
processes that are always killed, and CPU and memory readings from /proc.

Not a benchmark itself; ``bench_master.py`` and ``bench_slave.py`` import it from the
same directory.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import os
import platform
import re
import shlex
import signal
import statistics
import subprocess
import sys
import termios
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

HERE = os.path.dirname(os.path.abspath(__file__))
SERVERS = os.path.join(HERE, "bench_servers.py")
"""The script that runs the slaves the benchmarks talk to, in a process of their own."""

_TICKS = os.sysconf("SC_CLK_TCK")


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as cpuinfo:
            for line in cpuinfo:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def header() -> list[str]:
    """Date, machine, Python and the exact command, one line each."""
    versions = [f"{platform.python_implementation()} {platform.python_version()}"]
    with contextlib.suppress(ImportError):
        import pymodbus

        versions.append(f"pymodbus {pymodbus.__version__}")
    with contextlib.suppress(ImportError):
        from importlib.metadata import version

        import anyio  # noqa: F401

        versions.append(f"anyio {version('anyio')}")
    return [
        f"Date: {datetime.date.today().isoformat()}",
        f"Machine: {platform.platform()}; {cpu_model()}, {os.cpu_count()} logical CPUs",
        f"Python: {', '.join(versions)}",
        "Command: " + shlex.join(["python", *sys.argv]),
    ]


def add_section_argument(parser: argparse.ArgumentParser, sections: Mapping[str, object]) -> None:
    """``--section NAME`` (repeatable): run only these sections."""
    parser.add_argument(
        "--section", action="append", choices=list(sections), help="run only these sections"
    )


def run_sections(
    args: argparse.Namespace, sections: Mapping[str, Callable[[argparse.Namespace], list[str]]]
) -> None:
    """Print the :func:`header`, then each section chosen by ``--section`` (all by default)."""
    print("\n".join(header()))
    for name in args.section or list(sections):
        print()
        print("\n".join(sections[name](args)), flush=True)


def table(headers: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A Markdown table, columns padded to their widest cell."""
    widths = [max(len(str(cell)) for cell in column) for column in zip(headers, *rows, strict=True)]
    lines = [
        "| " + " | ".join(str(h).ljust(w) for h, w in zip(headers, widths, strict=True)) + " |",
        "|" + "|".join("-" * (w + 2) for w in widths) + "|",
    ]
    for row in rows:
        cells = (str(c).ljust(w) for c, w in zip(row, widths, strict=True))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def median(values: Sequence[float]) -> float:
    return statistics.median(values) if values else float("nan")


# -- processes -------------------------------------------------------------------------


def cpu_seconds(pid: int) -> float:
    """User + system CPU seconds of process *pid* (its threads included), from /proc."""
    with open(f"/proc/{pid}/stat", encoding="ascii") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    # After the command name: state is field 3, utime 14 and stime 15 (1-based).
    return (int(fields[11]) + int(fields[12])) / _TICKS


def cpu_exact(pid: int) -> float:
    """CPU seconds of process *pid*'s live threads, in nanoseconds' resolution (from
    /proc/PID/task/*/schedstat): for figures of a few tens of microseconds per request, below
    the 10 ms clock ticks of :func:`cpu_seconds`."""
    total = 0
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            total += int((task / "schedstat").read_text().split()[0])
        except (OSError, IndexError, ValueError):
            continue  # a thread that ended meanwhile
    return total / 1e9


def rss_kib(pid: int) -> int:
    """Resident memory of process *pid* in KiB (VmRSS)."""
    with open(f"/proc/{pid}/status", encoding="ascii") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    raise RuntimeError(f"no VmRSS for process {pid}")


class Children:
    """Child processes that are killed, whatever happens, when the ``with`` block ends."""

    def __init__(self) -> None:
        self.processes: list[subprocess.Popen[bytes]] = []

    def __enter__(self) -> Children:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.stop_all()

    def start(self, argv: Sequence[str], **options: object) -> subprocess.Popen[bytes]:
        process = subprocess.Popen(list(argv), start_new_session=True, **options)  # type: ignore[call-overload]
        self.processes.append(process)
        return process

    def stop(self, process: subprocess.Popen[bytes]) -> None:
        if process.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.pid, signal.SIGTERM)
            try:
                process.wait(3)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(process.pid, signal.SIGKILL)
                process.wait()
        for stream in (process.stdin, process.stdout, process.stderr):
            if stream is not None:
                stream.close()

    def stop_all(self) -> None:
        while self.processes:
            self.stop(self.processes.pop())

    def socat_pair(self) -> tuple[str, str]:
        """Start ``socat`` with two raw ptys joined; return their paths."""
        process = self.start(
            ["socat", "-d", "-d", "pty,raw,echo=0", "pty,raw,echo=0"],
            stderr=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
        )
        assert process.stderr is not None
        paths: list[str] = []
        deadline = time.monotonic() + 10
        while len(paths) < 2 and time.monotonic() < deadline:
            line = process.stderr.readline().decode(errors="replace")
            if not line:
                break
            found = re.search(r"PTY is (\S+)", line)
            if found:
                paths.append(found.group(1))
        if len(paths) < 2:
            raise RuntimeError("socat did not report two ptys")
        # Keep its stderr drained by closing our end: socat logs nothing more at -d -d
        # until it exits, and a closed pipe only matters then.
        return paths[0], paths[1]

    def server(self, *args: str) -> subprocess.Popen[bytes]:
        """Start ``bench_servers.py`` with *args*; return once it printed ``ready``."""
        process = self.start(
            [sys.executable, SERVERS, *args], stdout=subprocess.PIPE, stdin=subprocess.DEVNULL
        )
        assert process.stdout is not None
        line = process.stdout.readline().decode().strip()
        if line != "ready":
            raise RuntimeError(f"server {args} did not start: {line!r}")
        return process


def open_raw(path: str) -> int:
    """Open a pty slave device in raw mode, blocking, and return its descriptor."""
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
    iflag, oflag, cflag, lflag, ispeed, ospeed, cc = termios.tcgetattr(fd)
    iflag = 0
    oflag = 0
    lflag = 0
    cflag = (cflag & ~(termios.CSIZE | termios.PARENB)) | termios.CS8 | termios.CREAD
    cflag |= termios.CLOCAL
    cc[termios.VMIN] = 1
    cc[termios.VTIME] = 0
    termios.tcsetattr(fd, termios.TCSANOW, [iflag, oflag, cflag, lflag, ispeed, ospeed, cc])
    termios.tcflush(fd, termios.TCIOFLUSH)
    return fd


def read_exactly(fd: int, count: int) -> bytes:
    data = b""
    while len(data) < count:
        chunk = os.read(fd, count - len(data))
        if not chunk:
            raise EOFError
        data += chunk
    return data


# -- references with no Modbus logic: what the pty pair and the peer allow -------------------


def blocking_reads(path: str, request: bytes, reply: bytes, count: int) -> tuple[float, float]:
    """Send *request* and read *reply* back *count* times with blocking system calls.

    The cheapest client there is: no event loop and no Modbus logic, only the check that
    the reply is the expected bytes. Returns (reads/s, this process's CPU s per read).
    """
    fd = open_raw(path)
    try:
        for _ in range(20):
            os.write(fd, request)
            read_exactly(fd, len(reply))
        wall, cpu = time.perf_counter(), time.process_time()
        for _ in range(count):
            os.write(fd, request)
            if read_exactly(fd, len(reply)) != reply:
                raise AssertionError("the blocking client read a wrong reply")
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    finally:
        os.close(fd)
    return count / wall, cpu / count


async def bare_asyncio_reads(
    path: str, request: bytes, reply: bytes, count: int
) -> tuple[float, float]:
    """Like :func:`blocking_reads`, on an asyncio event loop: the port's descriptor is
    watched by the loop, each read awaits a future that the read callback completes.

    The cheapest async client there is: what any asyncio Modbus master pays before it
    does any Modbus work. Returns (reads/s, this process's CPU s per read).
    """
    import asyncio

    loop = asyncio.get_running_loop()
    fd = open_raw(path)
    os.set_blocking(fd, False)
    received = bytearray()
    waiter: list[asyncio.Future[bytes]] = []

    def on_readable() -> None:
        received.extend(os.read(fd, 256))
        if len(received) >= len(reply) and waiter:
            waiter.pop().set_result(bytes(received))
            received.clear()

    async def read_once() -> bytes:
        future = loop.create_future()
        waiter.append(future)
        os.write(fd, request)
        return await future

    loop.add_reader(fd, on_readable)
    try:
        for _ in range(20):
            await read_once()
        wall, cpu = time.perf_counter(), time.process_time()
        for _ in range(count):
            if await read_once() != reply:
                raise AssertionError("the bare asyncio client read a wrong reply")
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    finally:
        loop.remove_reader(fd)
        os.close(fd)
    return count / wall, cpu / count
