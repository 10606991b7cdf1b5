"""The library's loggers, and the handler that keeps them quiet until the application
configures logging.

Every module of aiortu that logs takes its logger from `get_logger`, so the package's
`NullHandler` is in place before the first record: without it, logging's last-resort
handler would print each warning on stderr. It lives here rather than in
`aiortu/__init__.py` so that importing aiortu (and `aiortu --help`) does not import
logging.
"""

from __future__ import annotations

import logging

logging.getLogger("aiortu").addHandler(logging.NullHandler())


def get_logger(name: str) -> logging.Logger:
    """The logger `name` (a module's `__name__`), under the package's quiet handler."""
    return logging.getLogger(name)
