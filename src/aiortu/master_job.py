"""Deprecated: internal now; use [`aiortu.master.Master`][aiortu.master.Master]. Importing
this module warns once."""

from aiortu._moved import forward_internal

# Reply was renamed JobResult, so that it is not mistaken for aiortu.slave.Reply.
__getattr__ = forward_internal(
    __name__,
    "aiortu.master._job",
    "use aiortu.master.Master, which queues its own transactions",
    {"Reply": "JobResult"},
)
