"""Deprecated: moved to [`aiortu.master`][aiortu.master]. Importing this module warns once."""

from aiortu._moved import Internal, forward

_RECORDS = "the master's file record methods take aiortu.core.pdu_files.{} objects or tuples"

__getattr__ = forward(
    __name__,
    "aiortu.master._handles",
    "aiortu.master",
    {
        "as_file_record": Internal(
            "aiortu.master._handles", "as_file_record", _RECORDS.format("FileRecord")
        ),
        "as_record_request": Internal(
            "aiortu.master._handles", "as_record_request", _RECORDS.format("FileRecordRequest")
        ),
    },
)
