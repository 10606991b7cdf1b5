"""Deprecated: moved to [`aiortu.master`][aiortu.master]. Importing this module warns once."""

from aiortu._moved import forward

__getattr__ = forward(__name__, "aiortu.master._serial_line", "aiortu.master")
