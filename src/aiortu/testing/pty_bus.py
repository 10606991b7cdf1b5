"""Deprecated: moved to [`aiortu.testing`][aiortu.testing]. Importing this module warns once."""

from aiortu._moved import forward

__getattr__ = forward(__name__, "aiortu.testing._pty_bus", "aiortu.testing")
