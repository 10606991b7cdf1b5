"""Mutation testing: do the tests notice when the code is changed in small ways?

Run from the repository root (slow: not part of CI)::

    nice -n 10 python benchmarks/mutation.py [--sample 20] [--seed 1] [--package gateway]

For each package of `PACKAGES`, every mutant of its source files is listed, a seeded sample
is drawn, and each sampled mutant is written into a copy of the repository (never the work
tree) and run against the package's tests only, stopping at the first failure, with a
timeout per mutant. A mutant is *killed* when a test fails (or the run times out or cannot
import), *survives* when every test passes. Printed: the kill ratio per package and every
survivor as `file:line  mutation`.

The mutations, on the syntax tree (docstrings, annotations, f-strings, asserts and logging
calls and decorators are left alone, and so is a line marked `# pragma: no mutate`):

- a comparison flipped (`==`/`!=`, `in`/`not in`, `is`/`is not`, `<` to `>=` or `<=`, ...);
- a `not` dropped;
- an `and` made `or` and the reverse; `True` and `False` swapped;
- an int constant changed by +1 and by -1;
- a guard removed: an `if` without `else` whose body ends in `return`, `raise`, `continue`
  or `break`.

The package to files and tests mapping is `PACKAGES`: globs from the repository root, so
that a module moved or renamed only needs its glob updated.
"""

from __future__ import annotations

import argparse
import ast
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


@dataclass(frozen=True)
class Package:
    """Source files to mutate and the tests that should notice, as globs from the root."""

    sources: tuple[str, ...]
    tests: tuple[str, ...]
    exclude_tests: tuple[str, ...] = ()


PACKAGES = {
    "core": Package(
        ("src/aiortu/core/**/*.py",),
        (
            "tests/core/**/test_*.py",
            # The core's state machines, plans and codes, tested beside their users.
            "tests/master/**/test_master_machine.py",
            "tests/master/**/test_poll_plan.py",
            "tests/slave/**/test_slave_machine.py",
            "tests/slave/**/test_serial_line_codes.py",
            "tests/project/test_errors.py",
        ),
    ),
    "gateway": Package(
        # With the framing of a listening connection (MBAP or RTU), the gateway's and the servers'.
        ("src/aiortu/gateway/**/*.py", "src/aiortu/transport/**/_server_framing.py"),
        ("tests/gateway/**/test_*.py",),
    ),
    "master engine": Package(
        (
            "src/aiortu/master/**/_engine*.py",
            "src/aiortu/master/**/_fast_path.py",
            "src/aiortu/master/**/_queue.py",
            "src/aiortu/master/**/_attempt.py",
            "src/aiortu/master/**/_line_state.py",
            "src/aiortu/master/**/_line_task.py",
        ),
        (
            "tests/master/**/test_engine_*.py",
            "tests/master/**/test_fast_path.py",
            "tests/faults/**/test_late_replies.py",
            "tests/master/**/test_master_api.py",
            "tests/master/**/test_master_faults.py",
            "tests/master/**/test_reconnect.py",
            "tests/master/**/test_tcp_master.py",
            "tests/master/**/test_fast_path_differential.py",
            "tests/faults/**/test_stale_replies.py",
            "tests/faults/**/test_master_misbehaving.py",
            "tests/project/test_trio.py",  # the engine's routes without an event loop
        ),
    ),
    "slave servers": Package(
        (
            "src/aiortu/slave/**/_slave.py",
            "src/aiortu/slave/**/_rtu_over_tcp.py",
            "src/aiortu/slave/**/_serve.py",
            "src/aiortu/slave/**/_tcp_server.py",
            "src/aiortu/slave/**/_dispatch.py",
            "src/aiortu/slave/**/_answer_at_once.py",
        ),
        ("tests/slave/**/test_*.py",),
        exclude_tests=("tests/slave/**/test_*interop*.py",),
    ),
}
"""What is mutated, and which tests run against it, by package."""

_COPY_IGNORE = shutil.ignore_patterns(
    ".git", ".venv", "__pycache__", ".hypothesis", ".*_cache", "site"
)
_PYTEST = ("-q", "-x", "-p", "no:cacheprovider", "--hypothesis-seed=0", "--no-header")


@dataclass(frozen=True)
class Mutant:
    """One change of one file: the bytes `start..end` replaced by `text`."""

    path: str
    line: int
    start: int
    end: int
    text: str
    description: str


@dataclass(frozen=True)
class Outcome:
    mutant: Mutant
    status: str  # "killed", "timeout", "error" (cannot import or collect) or "survived"
    seconds: float


# -- finding the mutants --------------------------------------------------------------

_FLIPS: dict[type[ast.cmpop], tuple[type[ast.cmpop], ...]] = {
    ast.Eq: (ast.NotEq,),
    ast.NotEq: (ast.Eq,),
    ast.Lt: (ast.GtE, ast.LtE),
    ast.LtE: (ast.Gt, ast.Lt),
    ast.Gt: (ast.LtE, ast.GtE),
    ast.GtE: (ast.Lt, ast.Gt),
    ast.In: (ast.NotIn,),
    ast.NotIn: (ast.In,),
    ast.Is: (ast.IsNot,),
    ast.IsNot: (ast.Is,),
}
_SYMBOLS = {
    ast.Eq: "==",
    ast.NotEq: "!=",
    ast.Lt: "<",
    ast.LtE: "<=",
    ast.Gt: ">",
    ast.GtE: ">=",
    ast.In: "in",
    ast.NotIn: "not in",
    ast.Is: "is",
    ast.IsNot: "is not",
}
_EXITS = (ast.Return, ast.Raise, ast.Continue, ast.Break)


def _skipped_nodes(tree: ast.AST) -> set[int]:
    """The ids of the nodes, with everything under them, that are never mutated."""
    roots = [root for node in ast.walk(tree) for root in _left_alone(node)]
    return {id(child) for root in roots for child in ast.walk(root)}


def _left_alone(node: ast.AST) -> Iterator[ast.AST]:
    """The parts of `node` that are not code to mutate: docstrings, annotations, ..."""
    body = getattr(node, "body", None)
    if isinstance(body, list) and body and _is_docstring(body[0]):
        yield body[0]
    if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
        yield from node.decorator_list  # @dataclass(slots=True) and the like
    if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.returns:
        yield node.returns
    if isinstance(node, (ast.AnnAssign, ast.arg)) and node.annotation is not None:
        yield node.annotation
    whole = (
        isinstance(node, (ast.JoinedStr, ast.Assert))
        or (isinstance(node, ast.Call) and _is_logging(node))
        or (isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test))
        or (
            isinstance(node, ast.Assign)
            and any(isinstance(name, ast.Name) and name.id == "__all__" for name in node.targets)
        )
    )
    if whole:
        yield node


def _is_docstring(node: ast.stmt) -> bool:
    return isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)


def _is_logging(call: ast.Call) -> bool:
    func = call.func
    return (
        isinstance(func, ast.Attribute)
        and isinstance(func.value, ast.Name)
        and func.value.id in {"_log", "log", "logger", "_logger"}
    )


def _changes(node: ast.AST, source: bytes) -> Iterator[tuple[str, str, bool]]:
    """The mutations of `node`: (new source, description, whether it is a statement)."""
    if isinstance(node, ast.Compare):
        for index, op in enumerate(node.ops):
            for new in _FLIPS[type(op)]:
                ops = list(node.ops)
                ops[index] = new()
                text = ast.unparse(ast.Compare(node.left, ops, node.comparators))
                yield text, f"`{_SYMBOLS[type(op)]}` -> `{_SYMBOLS[new]}`", False
    elif isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
        yield ast.unparse(node.operand), "`not` dropped", False
    elif isinstance(node, ast.BoolOp):
        new_op: ast.boolop = ast.Or() if isinstance(node.op, ast.And) else ast.And()
        words = ("and", "or") if isinstance(node.op, ast.And) else ("or", "and")
        yield ast.unparse(ast.BoolOp(new_op, node.values)), f"`{words[0]}` -> `{words[1]}`", False
    elif isinstance(node, ast.Constant) and type(node.value) is bool:
        yield repr(not node.value), f"`{node.value}` -> `{not node.value}`", False
    elif isinstance(node, ast.Constant) and type(node.value) is int:
        for step in (1, -1):
            new_value = node.value + step
            yield repr(new_value), f"`{node.value}` -> `{new_value}`", False
    elif isinstance(node, ast.If) and not node.orelse and isinstance(node.body[-1], _EXITS):
        start = _offset(source, node.lineno, node.col_offset)
        if not source[start:].startswith(b"elif"):
            yield "pass", f"guard removed: `if {ast.unparse(node.test)}: ...`", True


def _offset(source: bytes, line: int, column: int) -> int:
    """The byte offset of (`line`, `column`): the AST counts columns in UTF-8 bytes."""
    lines = source.splitlines(keepends=True)
    return sum(len(text) for text in lines[: line - 1]) + column


def mutants_of(path: Path, root: Path = ROOT) -> list[Mutant]:
    """Every mutant of the file at `path` (in the tree at `root`) that still compiles."""
    source = path.read_bytes()
    tree = ast.parse(source)
    skipped = _skipped_nodes(tree)
    lines = source.splitlines()
    found = []
    for node in ast.walk(tree):
        if id(node) in skipped or not hasattr(node, "end_col_offset"):
            continue
        if b"pragma: no mutate" in lines[node.lineno - 1]:
            continue
        start = _offset(source, node.lineno, node.col_offset)
        end = _offset(source, node.end_lineno or node.lineno, node.end_col_offset or 0)
        for text, description, statement in _changes(node, source):
            new = text if statement else f"({text})"
            mutant = Mutant(str(path.relative_to(root)), node.lineno, start, end, new, description)
            if _compiles(source, mutant):
                found.append(mutant)
    return found


def _compiles(source: bytes, mutant: Mutant) -> bool:
    try:
        compile(_applied(source, mutant), mutant.path, "exec")
    except SyntaxError:
        return False
    return True


def _applied(source: bytes, mutant: Mutant) -> bytes:
    return source[: mutant.start] + mutant.text.encode() + source[mutant.end :]


def _glob(patterns: tuple[str, ...], root: Path = ROOT) -> list[Path]:
    return sorted({path for pattern in patterns for path in root.glob(pattern)})


def sample(package: Package, size: int, seed: int, name: str, root: Path = ROOT) -> list[Mutant]:
    """A seeded sample of `size` mutants of `package` (in the tree at `root`), in file and
    line order."""
    every = [mutant for path in _glob(package.sources, root) for mutant in mutants_of(path, root)]
    chosen = random.Random(f"{seed}:{name}").sample(every, min(size, len(every)))
    return sorted(chosen, key=lambda mutant: (mutant.path, mutant.start, mutant.text))


# -- running them ----------------------------------------------------------------------


def package_tests(package: Package, root: Path = ROOT, mutated: str | None = None) -> list[str]:
    """The package's test files, those named after the mutated module first (they are the
    likeliest to fail, and the run stops at the first failure)."""
    excluded = set(_glob(package.exclude_tests, root))
    files = [path for path in _glob(package.tests, root) if path not in excluded]
    stem = Path(mutated).stem.lstrip("_") if mutated else ""
    files.sort(key=lambda path: not (stem and stem in path.stem))
    return [str(path.relative_to(root)) for path in files]


def _run_tests(
    copy: Path, tests: list[str], timeout: float, log: Path | None = None
) -> tuple[str, float]:
    """Run `tests` in `copy`: "passed", "failed", "error" or "timeout", and the seconds
    (pytest's output to `log`, or nowhere)."""
    shutil.rmtree(copy / ".hypothesis", ignore_errors=True)
    env = dict(os.environ, PYTHONPATH=str(copy / "src"), PYTHONDONTWRITEBYTECODE="1")
    began = time.monotonic()
    with open(log or os.devnull, "wb") as output:
        process = subprocess.Popen(
            [sys.executable, "-m", "pytest", *_PYTEST, *tests],
            cwd=copy,
            env=env,
            stdout=output,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        try:
            code = process.wait(timeout)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
            return "timeout", time.monotonic() - began
    seconds = time.monotonic() - began
    return {0: "passed", 1: "failed"}.get(code, "error"), seconds


def run_mutant(copy: Path, mutant: Mutant, tests: list[str], timeout: float) -> Outcome:
    """Write `mutant` into `copy`, run `tests`, put the file back."""
    target = copy / mutant.path
    original = target.read_bytes()
    target.write_bytes(_applied(original, mutant))
    log = copy / "mutant.log"
    try:
        result, seconds = _run_tests(copy, tests, timeout, log)
    finally:
        target.write_bytes(original)
    if result == "error":  # the mutant cannot be imported, or pytest could not run: say which
        print(*log.read_text(errors="replace").strip().splitlines()[-3:], sep="\n    ")
    status = {"passed": "survived", "failed": "killed"}.get(result, result)
    return Outcome(mutant, status, seconds)


def _arguments() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sample", type=int, default=20, help="mutants per package")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--package", action="append", choices=sorted(PACKAGES))
    parser.add_argument(
        "--timeout-factor",
        type=float,
        default=3.0,
        help="a mutant's timeout, in times the unmutated run of its tests (at least 60 s)",
    )
    parser.add_argument("--list", action="store_true", help="list the sample; run nothing")
    parser.add_argument(
        "--only",
        metavar="TEXT",
        action="append",
        help="run the sampled mutants whose `file:line` holds TEXT (given again: any of them)",
    )
    return parser.parse_args()


def _commit() -> str:
    def git(*words: str) -> str:
        done = subprocess.run(["git", *words], cwd=ROOT, capture_output=True, text=True, check=True)
        return done.stdout.strip()

    dirty = git("status", "--porcelain", "src", "tests")
    return git("rev-parse", "--short", "HEAD") + (" (with changes)" if dirty else "")


def run_package(copy: Path, name: str, args: argparse.Namespace) -> list[Outcome]:
    """Run the sample of package `name`; its unmutated tests must pass first."""
    package = PACKAGES[name]
    mutants = sample(package, args.sample, args.seed, name, copy)
    if args.only:
        mutants = [m for m in mutants if any(t in f"{m.path}:{m.line}" for t in args.only)]
    if args.list:
        for mutant in mutants:
            print(f"{name}: {mutant.path}:{mutant.line}  {mutant.description}")
        return []
    log = copy / f"unmutated-{name.replace(' ', '-')}.log"
    for _ in range(2):  # once more: a test that failed under the machine's load
        result, seconds = _run_tests(copy, package_tests(package, copy), 3600, log)
        if result == "passed":
            break
    else:
        tail = log.read_text(errors="replace").strip().splitlines()[-15:]
        print(f"{name}: skipped, the unmutated tests did not pass ({result}):", *tail, sep="\n  ")
        return []
    timeout = max(60.0, args.timeout_factor * seconds)
    print(f"{name}: tests pass in {seconds:.0f} s; {len(mutants)} mutants", flush=True)
    outcomes = []
    for mutant in mutants:
        outcome = run_mutant(copy, mutant, package_tests(package, copy, mutant.path), timeout)
        outcomes.append(outcome)
        print(
            f"  {outcome.status:8} {outcome.seconds:5.1f} s  {mutant.path}:{mutant.line}  "
            f"{mutant.description}",
            flush=True,
        )
    return outcomes


def report(results: dict[str, list[Outcome]]) -> None:
    """The kill ratio per package, then the survivors."""
    print("\n| package | mutants | killed | of which timeouts | survived | killed % |")
    print("|---|---|---|---|---|---|")
    for name, outcomes in results.items():
        counts = Counter(outcome.status for outcome in outcomes)
        killed = len(outcomes) - counts["survived"]
        ratio = f"{100 * killed / len(outcomes):.0f} %" if outcomes else "not run"
        print(f"| {name} | {len(outcomes)} | {killed} | {counts['timeout']} | "
              f"{counts['survived']} | {ratio} |")  # fmt: skip
    survivors = [o.mutant for outcomes in results.values() for o in outcomes
                 if o.status == "survived"]  # fmt: skip
    print(f"\nSurvivors ({len(survivors)}):")
    for mutant in survivors:
        print(f"  {mutant.path}:{mutant.line}  {mutant.description}")


def main() -> None:
    args = _arguments()
    names = args.package or list(PACKAGES)
    # Stopped, it still removes its copy of the repository.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit("stopped"))
    print(f"mutation testing at {_commit()}: {' '.join(sys.argv)}", flush=True)
    with tempfile.TemporaryDirectory(prefix="aiortu-mutants-") as folder:
        copy = Path(folder) / "repo"
        shutil.copytree(ROOT, copy, ignore=_COPY_IGNORE)
        results = {name: run_package(copy, name, args) for name in names}
    if not args.list:
        report(results)


if __name__ == "__main__":
    main()
