"""Deprecated: moved to [`aiortu.line`][aiortu.line]. Importing this module warns once."""

from aiortu._moved import forward

__getattr__ = forward(__name__, "aiortu.line._link", "aiortu.line")
