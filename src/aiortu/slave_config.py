"""Deprecated: moved to [`aiortu.slave`][aiortu.slave]. Importing this module warns once."""

from aiortu._moved import forward

__getattr__ = forward(__name__, "aiortu.slave._config", "aiortu.slave")
