"""The examples the help texts and the getting-started page give, run as given: the
virtual-bus help's serve, read and mbpoll lines; the gateway help's line shared with mbpoll;
the getting-started walk-through with a monitor watching; and a second virtual bus over a
running one, which must refuse; and every command's help examples, each one line that the
command's parser takes."""

from __future__ import annotations

import re
import shlex
import shutil
import socket
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from aiortu.cli import SUMMARIES, build_parser, main
from tests.cli.cli_helpers import aiortu_command, run_aiortu, start_aiortu

pytestmark = pytest.mark.timeout(90)

ROOT = Path(__file__).parents[2]
PAGE = (ROOT / "docs" / "getting-started.md").read_text()


def help_lines(command: str, section: str) -> list[list[str]]:
    """The command lines (as argument lists, comments dropped) of a section of `command`'s
    help that begins with `section`."""
    text = run_aiortu(command, "--help").stdout
    block = text.split(section, 1)[1].split("\n\n", 1)[0]
    lines = [line.split("#", 1)[0].strip() for line in block.splitlines()[1:]]
    return [shlex.split(line) for line in lines if line.startswith(("aiortu ", "mbpoll "))]


def as_run(argv: list[str], names: dict[str, str]) -> list[str]:
    """`argv` with the names of the example replaced, `aiortu` as this interpreter's."""
    argv = [names.get(word, word) for word in argv]
    return aiortu_command(*argv[1:]) if argv[0] == "aiortu" else argv


@contextmanager
def running(argv: list[str], ready: str, *, stream: str = "stderr") -> Iterator[None]:
    """`argv` running until the block ends, once a line of its `stream` has `ready`."""
    process = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               cwd=ROOT)  # fmt: skip
    try:
        pipe = process.stdout if stream == "stdout" else process.stderr
        assert pipe is not None
        line = pipe.readline()
        assert ready in line, line + pipe.read()
        yield
    finally:
        process.terminate()
        process.wait(timeout=10)


@contextmanager
def virtual_bus(tmp_path: Path, *options: str) -> Iterator[list[str]]:
    bus = start_aiortu("virtual-bus", *options, "--link-dir", str(tmp_path / "rtu"))
    try:
        assert bus.stdout is not None
        ports = int(options[options.index("--ports") + 1]) if "--ports" in options else 2
        yield [bus.stdout.readline().strip() for _ in range(ports)]
    finally:
        bus.terminate()
        bus.wait(timeout=10)


def run(argv: list[str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(argv, capture_output=True, text=True, timeout=30, check=False, cwd=ROOT)


def test_the_virtual_bus_help_reads_a_unit_the_example_file_has(tmp_path: Path) -> None:
    serve, read, mbpoll = help_lines("virtual-bus", "other programs need it said:")
    with virtual_bus(tmp_path) as ports:
        names = {"/dev/pts/5": ports[0], "/dev/pts/6": ports[1]}
        with running(as_run(serve, names), "Ctrl-C to stop"):
            result = run(as_run(read, names))
            assert (result.returncode, result.stderr) == (0, "")
            assert result.stdout == "40108 44609\n40109 22098\n40110 17216\n"
            if shutil.which("mbpoll"):
                polled = run(as_run(mbpoll, names))
                assert polled.returncode == 0, polled.stdout + polled.stderr
                assert "[108]: \t44609" in polled.stdout


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def test_the_gateway_help_shares_a_line_that_answers(tmp_path: Path) -> None:
    _, serve, gateway, mbpoll = help_lines("gateway", "two programs sharing one virtual line:")
    port = str(free_port())
    with virtual_bus(tmp_path) as ports:
        names = {"/dev/pts/5": ports[0], "/dev/pts/6": ports[1],
                 "tcp://127.0.0.1:1502": f"tcp://127.0.0.1:{port}", "1502": port}  # fmt: skip
        with (
            running(as_run(serve, names), "Ctrl-C to stop"),
            running(as_run(gateway, names), "shared on"),
        ):
            # What mbpoll asks, in aiortu's words: unit -a, reference 4xxxx from -r, count -c.
            flags = dict(zip(mbpoll[1:-1:2], mbpoll[2:-1:2], strict=False))
            ref = f"4{int(flags['-r']):04d}"
            result = run_aiortu("read", f"tcp://127.0.0.1:{port}", "--unit", flags["-a"],
                                "--ref", ref, "--count", flags["-c"])  # fmt: skip
            assert (result.returncode, result.stderr) == (0, "")
            if shutil.which("mbpoll"):
                polled = run(as_run(mbpoll, names))
                assert polled.returncode == 0, polled.stdout + polled.stderr
                assert "Illegal" not in polled.stdout + polled.stderr


def page_command(pattern: str) -> list[str]:
    found = re.search(pattern, PAGE)
    assert found is not None, pattern
    return shlex.split(found.group(1))


def test_getting_started_with_the_monitor_watching(tmp_path: Path) -> None:
    bus = page_command(r"\$ (aiortu virtual-bus [^\n]*)")
    monitor = page_command(r"`(aiortu monitor [^`]*)`")
    scan = page_command(r"`(aiortu scan [^`]*)`")
    links = str(tmp_path / "rtu")
    options = [links if word == "/tmp/rtu" else word for word in bus[2:]]
    bus_process = start_aiortu("virtual-bus", *options)
    try:
        assert bus_process.stdout is not None
        count = int(bus[bus.index("--ports") + 1])
        assert [bus_process.stdout.readline().strip() for _ in range(count)] == [
            f"{links}/port{i}" for i in range(count)
        ]
        names = {f"/tmp/rtu/port{i}": f"{links}/port{i}" for i in range(count)}
        here = ROOT / "examples" / "getting_started"
        slave = [sys.executable, str(here / "slave.py"), names["/tmp/rtu/port1"]]
        with (
            running(slave, "serving unit 1", stream="stdout"),
            running(as_run(monitor, names), "aiortu monitor"),
        ):
            master = run([sys.executable, str(here / "master.py"), names["/tmp/rtu/port0"]])
            assert master.returncode == 0, master.stderr
            assert master.stdout == "[215, 0, 0, 0]\n[215, 42, 0, 0]\n"
        with running(slave, "serving unit 1", stream="stdout"):
            found = run(as_run(scan, names))
            assert found.returncode == 0, found.stderr
            assert found.stdout.splitlines()[-1] == "found 1 unit (1) at 19200 8N2"
    finally:
        bus_process.terminate()
        bus_process.wait(timeout=10)


def test_a_second_virtual_bus_on_the_same_links_refuses(tmp_path: Path) -> None:
    with virtual_bus(tmp_path) as ports:
        links = sorted(p.name for p in (tmp_path / "rtu").iterdir())
        second = run_aiortu("virtual-bus", "--link-dir", str(tmp_path / "rtu"), timeout=10)
        assert second.returncode == 1
        assert second.stdout == ""
        assert re.fullmatch(
            rf"aiortu virtual-bus: {tmp_path / 'rtu'}: another virtual bus \(process \d+\) keeps "
            r"its links here: stop it, or give another directory\n",
            second.stderr,
        )
        # The first bus's links are still there, and still its own.
        assert sorted(p.name for p in (tmp_path / "rtu").iterdir()) == links
        assert (tmp_path / "rtu" / "port0").exists()
        assert ports == [str(tmp_path / "rtu" / "port0"), str(tmp_path / "rtu" / "port1")]


def example_commands(help_text: str) -> list[str]:
    """The command lines of the `examples:` section of a help text, each continued line (a `\\`
    at its end) joined to the next, comments, pipes and redirections dropped."""
    block = help_text.split("\nexamples:\n", 1)[1].split("\n\n", 1)[0]
    lines = [
        re.split(r" [#|>] ", line)[0].strip()
        for line in re.sub(r"\\\n\s*", " ", block).splitlines()
    ]
    return [line for line in lines if line.startswith("aiortu ")]


@pytest.mark.parametrize("command", sorted(SUMMARIES))
def test_every_help_example_is_one_line_the_command_takes(
    command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit):
        main([command, "--help"])
    examples = example_commands(capsys.readouterr().out)
    assert examples
    for line in examples:
        # A `\` that ends a line in the source but not in the text joins the next line on, its
        # indentation a gap in the middle of the command.
        assert "   " not in line, line
        argv = shlex.split(line)[1:]
        try:
            build_parser(argv[0]).parse_args(argv)
        except SystemExit as exit:
            pytest.fail(f"{line!r} exits {exit.code}")
