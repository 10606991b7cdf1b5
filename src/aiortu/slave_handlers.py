"""Deprecated: moved to [`aiortu.slave`][aiortu.slave]. Importing this module warns once."""

from aiortu._moved import Internal, forward

_BUILTIN = {
    "read_coils": "READ_COILS",
    "read_discrete_inputs": "READ_DISCRETE_INPUTS",
    "read_holding_registers": "READ_HOLDING_REGISTERS",
    "read_input_registers": "READ_INPUT_REGISTERS",
    "write_single_coil": "WRITE_SINGLE_COIL",
    "write_single_register": "WRITE_SINGLE_REGISTER",
    "read_exception_status": "READ_EXCEPTION_STATUS",
    "diagnostics": "DIAGNOSTICS",
    "get_comm_event_counter": "GET_COMM_EVENT_COUNTER",
    "get_comm_event_log": "GET_COMM_EVENT_LOG",
    "write_multiple_coils": "WRITE_MULTIPLE_COILS",
    "write_multiple_registers": "WRITE_MULTIPLE_REGISTERS",
    "report_server_id": "REPORT_SERVER_ID",
    "read_file_record": "READ_FILE_RECORD",
    "write_file_record": "WRITE_FILE_RECORD",
    "mask_write_register": "MASK_WRITE_REGISTER",
    "read_write_multiple_registers": "READ_WRITE_MULTIPLE_REGISTERS",
    "read_fifo_queue": "READ_FIFO_QUEUE",
    "read_device_identification": "ENCAPSULATED_INTERFACE_TRANSPORT",
}
"""Each built-in handler function, and the function code it serves."""

_FAST = "aiortu.slave.Slave takes its fast paths by itself; there is nothing to register"

__getattr__ = forward(
    __name__,
    "aiortu.slave._handlers",
    "aiortu.slave",
    {
        **{
            name: Internal(
                "aiortu.slave._handlers",
                name,
                f"use aiortu.slave.BUILTIN_HANDLERS[aiortu.FunctionCode.{code}]",
            )
            for name, code in _BUILTIN.items()
        },
        "FAST_PATHS": Internal("aiortu.slave._answer_at_once", "FAST_PATHS", _FAST),
        "FastPath": Internal("aiortu.slave._answer_at_once", "FastPath", _FAST),
    },
)
