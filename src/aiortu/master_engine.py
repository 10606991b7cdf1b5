"""Deprecated: moved to [`aiortu.master`][aiortu.master]. Importing this module warns once."""

from aiortu._moved import Internal, forward

__getattr__ = forward(
    __name__,
    "aiortu.master._engine",
    "aiortu.master",
    {
        "LineEngine": Internal(
            "aiortu.master._engine",
            "LineEngine",
            "use aiortu.master.Master, which runs one for its line",
        ),
    },
)
