"""Count the waits on the real clock that the tests make, as a pytest plugin.

Run from the repository root::

    python -m pytest -p benchmarks.real_waits tests/gateway tests/master [-q]
        [--real-waits-report waits.tsv]

A real wait is a call from a file under `tests/` of `anyio.sleep`, `asyncio.sleep`,
`trio.sleep` or `time.sleep` with a delay above zero, or a scope of `anyio.move_on_after`,
`move_on_at`, `fail_after` or `fail_at` that ran out, made while the event loop tells the
real time (not on `tests/virtual_clock.py`'s `VirtualTimeLoop` or trio's `MockClock`). At
the end it prints the count, the real seconds they took (a sleep as measured, a scope that
ran out its own length), and the tests that waited longest; `--real-waits-report` writes
every test's count and seconds to a file (tab-separated). Waits that the library makes on
a test's behalf (a response timeout run out inside the master) are not counted: the tests'
durations show them.

Run as a script, it counts the sleeps in the test files instead, without running them: calls
of those four sleeps with a nonzero number as the delay, split by whether the test or helper
they are in runs on the virtual clock (an `on_virtual_clock` test)::

    python benchmarks/real_waits.py [tests]
"""

from __future__ import annotations

import ast
import asyncio
import contextlib
import sys
import time
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import anyio
import pytest
import trio
import trio.testing

_TESTS = str(Path(__file__).resolve().parent.parent / "tests")
_count: Counter[str] = Counter()
_seconds: Counter[str] = Counter()
_current = ["(collection)"]


def _virtual() -> bool:
    """Whether the running event loop (if any) runs on a virtual clock."""
    with contextlib.suppress(RuntimeError):
        return type(asyncio.get_running_loop()).__name__ == "VirtualTimeLoop"
    with contextlib.suppress(RuntimeError):
        return isinstance(trio.lowlevel.current_clock(), trio.testing.MockClock)
    return False


def _real(depth: int) -> bool:
    """Whether the caller `depth` frames up is a test's, on the real clock."""
    return sys._getframe(depth).f_code.co_filename.startswith(_TESTS) and not _virtual()


def _note(seconds: float) -> None:
    _count[_current[0]] += 1
    _seconds[_current[0]] += seconds


def _sleeping(sleep: Callable[..., Any]) -> Callable[..., Any]:
    """`sleep`, counting the real time it takes where a test asks for a real wait."""
    if asyncio.iscoroutinefunction(sleep):

        async def async_sleep(delay: float, *args: Any, **kwargs: Any) -> Any:
            if delay <= 0 or not _real(2):
                return await sleep(delay, *args, **kwargs)
            start = time.perf_counter()
            try:
                return await sleep(delay, *args, **kwargs)
            finally:
                _note(time.perf_counter() - start)

        return async_sleep

    def sync_sleep(delay: float) -> None:
        if delay > 0 and _real(2):
            _note(delay)
        sleep(delay)

    return sync_sleep


def _scoping(make: Callable[..., Any], absolute: bool) -> Callable[..., Any]:
    @contextlib.contextmanager
    def scoped(delay: float, *args: Any, **kwargs: Any) -> Iterator[Any]:
        length = delay - anyio.current_time() if absolute else delay
        with make(delay, *args, **kwargs) as scope:
            try:
                yield scope
            except TimeoutError:
                if _real(3):
                    _note(length)
                raise
        if scope.cancelled_caught and _real(3):
            _note(length)

    return scoped


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--real-waits-report",
        metavar="PATH",
        help="write each test's real waits and their seconds to PATH (tab-separated)",
    )


def pytest_configure(config: pytest.Config) -> None:
    for module, name in ((anyio, "sleep"), (asyncio, "sleep"), (trio, "sleep"), (time, "sleep")):
        setattr(module, name, _sleeping(getattr(module, name)))
    for name, absolute in (
        ("move_on_after", False),
        ("fail_after", False),
        ("move_on_at", True),
        ("fail_at", True),
    ):
        setattr(anyio, name, _scoping(getattr(anyio, name), absolute))


def pytest_runtest_logstart(nodeid: str) -> None:
    _current[0] = nodeid


def pytest_terminal_summary(terminalreporter: Any, config: pytest.Config) -> None:
    report = config.getoption("--real-waits-report")
    if report:
        with open(report, "w") as file:
            for nodeid in sorted(_count):
                file.write(f"{nodeid}\t{_count[nodeid]}\t{_seconds[nodeid]:.4f}\n")
    write = terminalreporter.write_line
    write(
        f"real waits in test code: {sum(_count.values())} in {len(_count)} tests,"
        f" {sum(_seconds.values()):.1f} s"
    )
    for nodeid, seconds in _seconds.most_common(30):
        write(f"  {_count[nodeid]:3d} waits {seconds:7.2f} s  {nodeid}")


_SLEEPS = {"anyio", "asyncio", "trio", "time"}


def _literal_sleeps(node: ast.AST) -> int:
    """The calls in `node` of `MODULE.sleep(N)`, MODULE one of `_SLEEPS` and N a number > 0."""
    count = 0
    for call in ast.walk(node):
        if not (isinstance(call, ast.Call) and isinstance(call.func, ast.Attribute)):
            continue
        owner, args = call.func.value, call.args
        if not (call.func.attr == "sleep" and isinstance(owner, ast.Name)):
            continue
        if owner.id in _SLEEPS and args and isinstance(args[0], ast.Constant):
            count += isinstance(args[0].value, int | float) and args[0].value > 0
    return count


def static_count(root: Path) -> tuple[int, int]:
    """The literal sleeps under `root`: (in tests on the virtual clock, anywhere else)."""
    virtual = other = 0
    for path in sorted(root.rglob("*.py")):
        for node in ast.parse(path.read_text()).body:
            count = _literal_sleeps(node)
            decorators = getattr(node, "decorator_list", [])
            if any(isinstance(d, ast.Name) and d.id == "on_virtual_clock" for d in decorators):
                virtual += count
            else:
                other += count
    return virtual, other


if __name__ == "__main__":
    virtual, other = static_count(Path(sys.argv[1] if len(sys.argv) > 1 else "tests"))
    print(
        f"sleeps with a nonzero literal delay: {virtual + other}; in tests on the virtual"
        f" clock {virtual}, elsewhere (real time, or helpers of both) {other}"
    )
