"""Every ```python block of README.md and docs/*.md runs in the suite, or says why it cannot.

A marker line right above each block says how the block is tested:

    <!-- test: KIND[, endless[, kept]][, thread][; expect EXPRESSION][; prints] -->
    <!-- test: compile: REASON -->

KIND is one of

- `run`: the block runs as it is. The blocks of a page share one namespace and run in
  the page's order, as a reader would type them in one session; `await` may be used at
  the top level.
- `master`: as `run`, with `master` bound to a `Master` on an in-memory line to the
  simulated devices below (units 1, 2, 3 and 17, every table).
- `program with devices`: as `run`, while the simulated devices serve on pty port 1.
- `slave`: as `run`, with `slave` bound to a `Slave` serving the page's `store` as unit
  17 on an in-memory line.
- `pytest`: the block is a test module; it runs in its own pytest, which must pass
  without a warning. Its leading `# pyproject.toml:` comment lines are the config.

The hardware the docs name is replaced by virtual lines: serial device paths by the two
ports of a pty bus ("/dev/ttyUSB0" is port 0, "/dev/ttyUSB1" port 1), parity E by N
(a pty keeps no parity), a device server's address by a local TCP listener, and
`anyio.run(main)` by `await main()`.

`thread` runs the block in a worker thread, so that the event loop goes on serving the
devices while the block blocks (the blocking API's blocks). `endless` runs the block in the
background until every task waits, checks the expectation, then cancels it (`kept`: at the
end of the page). EXPRESSION is evaluated (await allowed) with `line`, a master on the
in-memory line of `stream` or `slave`, and `port`, a master on pty port 0. `prints` compares
what the block printed with the ```console block that follows it. `compile` only compiles the
block: REASON says what the block needs that a test machine does not have.
"""

from __future__ import annotations

import ast
import contextlib
import inspect
import io
import re
import subprocess
import sys
import textwrap
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import anyio
import anyio.abc
import pytest
from anyio import wait_all_tasks_blocked

import aiortu
from aiortu.slave import ServerId
from aiortu.testing import VirtualBus

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
# A block may be indented (inside a tab or an admonition); its marker then is too.
BLOCK = re.compile(
    r"^(?P<indent>[ \t]*)```python[^\n]*\n(?P<code>.*?)^(?P=indent)```[ \t]*$", re.M | re.S
)
MARKER = re.compile(r"^[ \t]*<!-- test: (?P<spec>.+?) -->\s*$")
PORT_NAMES = {
    0: ("/dev/ttyUSB0", "/tmp/rtu/port0", "/dev/pts/5", "/dev/ttyS1"),
    1: ("/dev/ttyUSB1", "/tmp/rtu/port1", "/dev/pts/6"),
}
KINDS = ("run", "master", "program with devices", "slave", "pytest")


@dataclass
class Block:
    """One python block of a page and how its marker says to test it."""

    page: str
    line: int
    code: str
    kind: str
    endless: bool = False
    kept: bool = False
    thread: bool = False
    expect: str | None = None
    prints: str | None = None
    reason: str | None = None

    @property
    def where(self) -> str:
        return f"{self.page}:{self.line}"


def _parse_marker(spec: str) -> dict[str, Any]:
    if spec.startswith("compile:"):
        reason = spec.removeprefix("compile:").strip()
        assert reason, "a compile-only block says why it cannot run"
        return {"kind": "compile", "reason": reason}
    head, *clauses = (part.strip() for part in spec.split(";"))
    kind, *flags = (part.strip() for part in head.split(","))
    assert kind in KINDS, f"unknown kind {kind!r}; the kinds are {', '.join(KINDS)}"
    assert set(flags) <= {"endless", "kept", "thread"}, flags
    found: dict[str, Any] = {
        "kind": kind,
        "endless": "endless" in flags,
        "kept": "kept" in flags,
        "thread": "thread" in flags,
    }
    for clause in clauses:
        if clause.startswith("expect "):
            found["expect"] = clause.removeprefix("expect ")
        else:
            assert clause == "prints", clause
            found["prints"] = ""
    return found


def blocks_of(page: Path) -> list[Block]:
    text = page.read_text(encoding="utf-8")
    name = str(page.relative_to(ROOT))
    found = []
    for match in BLOCK.finditer(text):
        line = text.count("\n", 0, match.start()) + 1
        before = text[: match.start()].rstrip("\n").rsplit("\n", 1)[-1]
        marker = MARKER.match(before)
        code = textwrap.dedent(match.group("code"))
        try:
            assert marker, "a python block needs a <!-- test: ... --> line above it"
            block = Block(name, line, code, **_parse_marker(marker.group("spec")))
            if block.prints is not None:
                console = re.search(r"```console\n(.*?)```", text[match.end() :], re.S)
                assert console, "'prints' needs a console block after the python block"
                shown = [ln for ln in console.group(1).splitlines() if not ln.startswith("$")]
                block.prints = "\n".join(shown)
        except AssertionError as error:
            # Reported by a test, so that one bad marker does not stop the collection.
            block = Block(name, line, code, kind="unmarked", reason=str(error))
        found.append(block)
    return found


ALL_BLOCKS = [block for page in PAGES for block in blocks_of(page)]
PAGES_WITH_CODE = sorted({block.page for block in ALL_BLOCKS})


def test_every_python_block_says_how_it_is_tested() -> None:
    problems = [f"{b.where}: {b.reason}" for b in ALL_BLOCKS if b.kind == "unmarked"]
    assert problems == []


def test_the_docs_have_python_blocks_and_most_of_them_run() -> None:
    compiled = [block for block in ALL_BLOCKS if block.kind == "compile"]
    assert len(ALL_BLOCKS) >= 25
    assert len(compiled) <= 8, [block.where for block in compiled]


@pytest.mark.parametrize("where", [b.where for b in ALL_BLOCKS if b.kind == "compile"])
def test_a_block_that_needs_hardware_compiles(where: str) -> None:
    block = next(block for block in ALL_BLOCKS if block.where == where)
    compile(block.code, where, "exec", flags=ast.PyCF_ALLOW_TOP_LEVEL_AWAIT)


# -- the simulated devices and the virtual hardware -------------------------------------


def device_store() -> aiortu.MemoryStore:
    """A unit with every table, FIFO, file and identification the guides' blocks use."""
    return aiortu.MemoryStore(
        coils={0: 0x400},
        discrete_inputs={0: 0x400},
        holding_registers={0: 0x400},
        input_registers={0: 0x400},
        fifo_queues={0x04DE: [440, 25]},
        files={3: 20, 4: 20},
        device_identification={0: "aiortu", 1: "SIM-1", 2: "1.0"},
        server_id=ServerId(b"\x11", True, b"sim"),
    )


def devices() -> dict[int, aiortu.MemoryStore]:
    return {unit: device_store() for unit in (1, 2, 3, 17)}


@contextlib.asynccontextmanager
async def in_memory_line(
    serve: Callable[[anyio.abc.ByteStream], Any] | None,
) -> AsyncIterator[tuple[aiortu.Master, VirtualBus]]:
    """A master on one end of an in-memory line; *serve* (if any) gets the other end."""
    bus = VirtualBus(2)
    async with contextlib.AsyncExitStack() as stack:
        stack.callback(bus.close)
        if serve is not None:
            await stack.enter_async_context(serve(bus.endpoints[1]))
        master = await stack.enter_async_context(
            aiortu.Master(bus.endpoints[0], frame_gap=0, timeout=1.0)
        )
        yield master, bus


async def _hold(stream: anyio.abc.SocketStream) -> None:
    """A device server that takes connections and never answers."""
    async with stream:
        with contextlib.suppress(anyio.EndOfStream, anyio.BrokenResourceError):
            while True:
                await stream.receive()


@dataclass
class Page:
    """What the blocks of one page share: a namespace, the virtual hardware, the output."""

    paths: tuple[str, ...]
    tcp_port: int
    group: anyio.abc.TaskGroup
    output: io.StringIO
    namespace: dict[str, Any] = field(default_factory=lambda: {"__name__": "__docs__"})
    stream_master: aiortu.Master | None = None
    kept: list[anyio.CancelScope] = field(default_factory=list)

    def prepare(self, code: str) -> str:
        # One pass: a pty's own path may be one of the names the docs use (/dev/pts/6).
        ports = {f'"{name}"': port for port, names in PORT_NAMES.items() for name in names}
        pattern = "|".join(re.escape(name) for name in ports)
        code = re.sub(pattern, lambda m: f'"{self.paths[ports[m.group(0)]]}"', code)
        code = code.replace('parity="E"', 'parity="N"').replace('"E", 1)', '"N", 1)')
        code = code.replace('"192.168.1.50", 4001', f'"127.0.0.1", {self.tcp_port}')
        code = code.replace("192.168.1.50:4001", f"127.0.0.1:{self.tcp_port}")
        code = re.sub(r"^([ \t]*)anyio\.run\((\w+)\)[ \t]*$", r"\1await \2()", code, flags=re.M)
        return re.sub(r"^([ \t]*)asyncio\.run\(", r"\1await (", code, flags=re.M)

    async def execute(self, block: Block, namespace: dict[str, Any]) -> None:
        code = compile(
            self.prepare(block.code), block.where, "exec", flags=ast.PyCF_ALLOW_TOP_LEVEL_AWAIT
        )
        if block.thread:
            await anyio.to_thread.run_sync(eval, code, namespace)
            return
        result = eval(code, namespace)
        if inspect.iscoroutine(result):
            await result


async def check_expectation(page: Page, block: Block, line: aiortu.Master | None) -> None:
    if block.expect is None:
        return
    async with contextlib.AsyncExitStack() as stack:
        names = {**page.namespace, "line": line or page.stream_master, "aiortu": aiortu}
        if "port" in block.expect:
            names["port"] = await stack.enter_async_context(
                # Not exclusive: a port still closing (under load) must not lock out the
                # next block's program.
                aiortu.open_master(
                    page.paths[0], parity="N", timeout=2.0, reconnect=False, exclusive=False
                )
            )
        expression = compile(
            block.expect, block.where, "eval", flags=ast.PyCF_ALLOW_TOP_LEVEL_AWAIT
        )
        # A background block may still be starting (a port opens in a worker thread, a
        # poller's first cycle runs): evaluate until it holds, within a generous bound.
        last: object = None
        with anyio.move_on_after(20):
            while True:
                try:
                    last = eval(expression, names)
                    if inspect.iscoroutine(last):
                        last = await last
                except aiortu.ModbusError as error:
                    last = error
                if last is True or (last and not isinstance(last, Exception)):
                    return
                await anyio.sleep(0.05)
        raise AssertionError(f"{block.where}: expected {block.expect}, got {last!r}")


async def run_block(page: Page, block: Block, namespace: dict[str, Any], line: Any) -> None:
    """Run one block: to its end, or (endless) until every task waits."""
    if not block.endless:
        with anyio.fail_after(30):
            await page.execute(block, namespace)
        await check_expectation(page, block, line)
        return
    scope = anyio.CancelScope()
    failure: list[BaseException] = []

    async def background() -> None:
        with scope:
            try:
                await page.execute(block, namespace)
            except Exception as error:
                failure.append(error)

    page.group.start_soon(background)
    await wait_all_tasks_blocked()
    assert not failure, f"{block.where}: {failure[0]!r}"
    await check_expectation(page, block, line)
    assert not failure, f"{block.where}: {failure[0]!r}"
    if block.kept:
        page.kept.append(scope)
    else:
        scope.cancel()


async def run_with_context(page: Page, block: Block) -> None:
    namespace = page.namespace
    if block.kind == "master":
        async with in_memory_line(lambda end: aiortu.Slave(end, devices(), frame_gap=0)) as (
            master,
            _,
        ):
            namespace["master"] = master
            await run_block(page, block, namespace, master)
    elif block.kind == "slave":
        slave: list[aiortu.Slave] = []

        def serve(end: anyio.abc.ByteStream) -> aiortu.Slave:
            slave.append(aiortu.Slave(end, {17: namespace["store"]}, frame_gap=0))
            return slave[0]

        async with in_memory_line(serve) as (master, _):
            namespace["slave"] = slave[0]
            await run_block(page, block, namespace, master)
    elif block.kind == "program with devices":
        async with aiortu.serve(page.paths[1], devices(), parity="N", exclusive=False):
            await run_block(page, block, namespace, None)
    else:
        await run_block(page, block, namespace, None)


def run_pytest_blocks(blocks: list[Block], directory: Path) -> None:
    """Run a page's pytest blocks as one suite: one pytest, which must pass without a warning."""
    for block in blocks:
        # The config of the page's first pytest block holds for the later ones.
        lines = block.code.splitlines()
        if (
            lines
            and lines[0].startswith("# pyproject.toml:")
            and not (directory / "pyproject.toml").exists()
        ):
            config = []
            for line in lines[1:]:
                if not line.startswith("# "):
                    break
                config.append(line.removeprefix("# "))
            (directory / "pyproject.toml").write_text("\n".join(config) + "\n", encoding="utf-8")
        (directory / f"test_block_{block.line}.py").write_text(block.code, encoding="utf-8")
    result = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-W", "error", directory],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        cwd=directory,
    )
    where = ", ".join(block.where for block in blocks)
    assert result.returncode == 0, f"{where}:\n{result.stdout}\n{result.stderr}"
    assert "warning" not in result.stdout.lower(), f"{where}:\n{result.stdout}"


@pytest.mark.parametrize("page_name", PAGES_WITH_CODE)
async def test_the_python_blocks_of_a_page_run(
    page_name: str, pty_bus: Any, tmp_path: Path
) -> None:
    blocks = [block for block in ALL_BLOCKS if block.page == page_name]
    bus = pty_bus(ports=2)
    output = io.StringIO()
    async with contextlib.AsyncExitStack() as stack:
        listener = await stack.enter_async_context(
            await anyio.create_tcp_listener(local_host="127.0.0.1")
        )
        tcp_port = listener.extra(anyio.abc.SocketAttribute.local_port)
        line, line_bus = await stack.enter_async_context(in_memory_line(None))
        async with anyio.create_task_group() as group:
            group.start_soon(listener.serve, _hold)
            page = Page(bus.paths, tcp_port, group, output)
            # `stream` is the other end of the line that `line` masters in expectations.
            page.namespace["stream"] = line_bus.endpoints[1]
            page.stream_master = line
            with contextlib.redirect_stdout(output):
                for block in blocks:
                    await run_page_block(page, block, tmp_path)
            for scope in page.kept:
                scope.cancel()
            group.cancel_scope.cancel()


async def run_page_block(page: Page, block: Block, tmp_path: Path) -> None:
    if block.kind in ("compile", "unmarked"):
        return
    if block.kind == "pytest":
        suite = [b for b in ALL_BLOCKS if b.page == block.page and b.kind == "pytest"]
        if block is suite[0]:
            run_pytest_blocks(suite, tmp_path)
        return
    start = page.output.tell()
    await run_with_context(page, block)
    if block.prints is not None:
        printed = page.output.getvalue()[start:].splitlines()
        shown = iter(printed)
        missing = [line for line in block.prints.splitlines() if line not in shown]
        assert not missing, f"{block.where}: {missing} not printed in order; printed {printed}"
