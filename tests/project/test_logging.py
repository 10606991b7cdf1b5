"""The library logs to nobody until the application configures logging: every module that
logs takes its logger from `aiortu._log`, which puts a NullHandler on the package's logger,
so logging's last-resort handler never prints a record on stderr. Importing aiortu itself
does not import logging (`aiortu --help` starts without it)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import aiortu

SOURCE = Path(aiortu.__file__).parent


def _run(*code: str) -> str:
    result = subprocess.run(
        [sys.executable, "-c", "\n".join(code)], capture_output=True, text=True, timeout=30,
        check=True,
    )  # fmt: skip
    return result.stdout.strip()


def test_every_module_that_logs_takes_its_logger_from_the_package() -> None:
    # The command line configures handlers of its own; the library only logs.
    library = [path for path in SOURCE.rglob("*.py") if "cli" not in path.relative_to(SOURCE).parts]
    loggers = [path.name for path in library if "getLogger(" in path.read_text(encoding="utf-8")]
    assert loggers == ["_log.py"]


def test_a_warning_of_the_library_reaches_no_stderr_by_default() -> None:
    result = subprocess.run(
        [sys.executable, "-c", "import aiortu.master; import logging; "
         "logging.getLogger('aiortu.master._connection').warning('the line failed')"],
        capture_output=True, text=True, timeout=30, check=True,
    )  # fmt: skip
    assert result.stderr == ""


def test_importing_aiortu_does_not_import_logging() -> None:
    assert _run("import sys, aiortu", "print('logging' in sys.modules)") == "False"
