"""`python -m aiortu`: the same as the `aiortu` command."""

from __future__ import annotations

from aiortu.cli import main

__all__ = ()

if __name__ == "__main__":
    raise SystemExit(main())
