"""Start-up time of the ``aiortu`` command in two source trees, interleaved, median of 10.

    python benchmarks/bench_startup.py BEFORE/src AFTER/src

(for the tree before, ``git archive COMMIT src | tar -x -C DIR``). Prints a Markdown table.
"""

import os
import statistics
import subprocess
import sys
import time

trees = {"before": sys.argv[1], "after": sys.argv[2]}
entry = "import sys; from aiortu.cli import main; sys.exit(main())"
commands = {
    "python -m aiortu --help": ["-m", "aiortu", "--help"],
    "aiortu --help": ["-c", entry, "--help"],
    "aiortu read --help": ["-c", entry, "read", "--help"],
    "python -c pass": ["-c", "pass"],
}
runs = {(c, t): [] for c in commands for t in trees}
for _ in range(10):
    for c, argv in commands.items():
        for t, src in trees.items():
            env = {**os.environ, "PYTHONPATH": src}
            start = time.perf_counter()
            subprocess.run([sys.executable, *argv], env=env, stdout=subprocess.DEVNULL, check=True)
            runs[c, t].append(time.perf_counter() - start)
for c in commands:
    b, a = (statistics.median(runs[c, t]) * 1000 for t in trees)
    print(f"| `{c}` | {b:.0f} ms | {a:.0f} ms |")
