"""Start-up time of the ``aiortu`` command in one or two source trees, interleaved, median of 7.

    python benchmarks/bench_startup.py AFTER/src
    python benchmarks/bench_startup.py BEFORE/src AFTER/src

(for the tree before, ``git archive COMMIT src | tar -x -C DIR``). ``aiortu read`` reads
three holding registers from ``aiortu serve tcp://127.0.0.1:0 --config
examples/devices.toml`` (run from the last tree), so it is the whole command: start-up,
connect, one request, exit. Each tree's bytecode is written once to a temporary cache
before the runs (``PYTHONPYCACHEPREFIX``), as an installed package has its own; a shell
that sets ``PYTHONDONTWRITEBYTECODE`` would otherwise compile every module on every run.
Prints a Markdown table: the median wall time of the process, and its CPU time (user +
system), which moves less with the load of a shared machine.
"""

import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RUNS = 7
trees = dict(zip(("before", "after"), sys.argv[1:], strict=False))
if len(sys.argv) == 2:
    trees = {"after": sys.argv[1]}
entry = "import sys; from aiortu.cli import main; sys.exit(main())"
devices = str(Path(__file__).resolve().parent.parent / "examples" / "devices.toml")
cache = tempfile.mkdtemp(prefix="aiortu-bytecode-")
base = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def env(src: str) -> dict[str, str]:
    return {**base, "PYTHONPATH": src, "PYTHONPYCACHEPREFIX": os.path.join(cache, src.strip("/"))}


server = subprocess.Popen(
    [sys.executable, "-c", entry, "serve", "tcp://127.0.0.1:0", "--config", devices],
    env=env(list(trees.values())[-1]),
    stderr=subprocess.PIPE,
    text=True,
)
assert server.stderr is not None
port = re.search(r"\(port (\d+)\)", server.stderr.readline())
assert port is not None, "the server did not start"
url = f"tcp://127.0.0.1:{port.group(1)}"
READ = ["--unit", "17", "--ref", "40108", "--count", "3"]
commands = {
    "python -m aiortu --help": ["-m", "aiortu", "--help"],
    "aiortu --help": ["-c", entry, "--help"],
    "aiortu read --help": ["-c", entry, "read", "--help"],
    "aiortu read tcp://... (3 registers)": ["-c", entry, "read", url, *READ],
    "python -c pass": ["-c", "pass"],
}


def run(argv: list[str], src: str) -> tuple[float, float]:
    """One run's wall and CPU seconds."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run([sys.executable, *argv], env=env(src), stdout=subprocess.DEVNULL, check=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime


try:
    for src in trees.values():
        run(commands["aiortu read tcp://... (3 registers)"], src)  # writes the bytecode
    runs: dict[tuple[str, str], list[tuple[float, float]]] = {
        (c, t): [] for c in commands for t in trees
    }
    for _ in range(RUNS):
        for c, argv in commands.items():
            for t, src in trees.items():
                runs[c, t].append(run(argv, src))
finally:
    server.terminate()
    server.wait()
print("| command | " + " | ".join(f"{t} wall | {t} CPU" for t in trees) + " |")
print("|---|" + "---|---|" * len(trees))
for c in commands:
    cells = []
    for t in trees:
        walls, cpus = zip(*runs[c, t], strict=True)
        cells.append(f"{statistics.median(walls) * 1000:.0f} ms")
        cells.append(f"{statistics.median(cpus) * 1000:.0f} ms")
    print(f"| `{c}` | " + " | ".join(cells) + " |")
