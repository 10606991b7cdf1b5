"""The state machines of a master and a slave, their transactions and the slave's
event log, with the drawing of their tables."""

from __future__ import annotations

from aiortu._public import publish
from aiortu.core.machines._comm_events import (
    EVENT_ENTERED_LISTEN_ONLY,
    EVENT_RESTART,
    MAX_EVENTS,
    CommEventLog,
    receive_event,
    send_event,
)
from aiortu.core.machines._diagrams import (
    state_diagram,
)
from aiortu.core.machines._master_machine import (
    DEFAULT_FRAME_ERROR_GRACE,
    KnownRequest,
    MasterEvent,
    MasterMachine,
    MasterMachineError,
    MasterState,
    TransitionObserver,
)
from aiortu.core.machines._master_transaction import (
    DEFAULT_RETRY_ON,
    SAFE_TO_REPEAT,
    Failure,
    Outcome,
    OutcomeKind,
    RetryPolicy,
    SkipReason,
    Transaction,
    frame_error_from_discard,
)
from aiortu.core.machines._slave_machine import (
    DEFAULT_ASCII_DELIMITER,
    NEGATIVE_ACKNOWLEDGE,
    SerialLineCounters,
    SlaveEvent,
    SlaveMachine,
    SlaveMachineError,
    SlaveState,
)

__all__ = (
    "CommEventLog",
    "DEFAULT_ASCII_DELIMITER",
    "DEFAULT_FRAME_ERROR_GRACE",
    "DEFAULT_RETRY_ON",
    "EVENT_ENTERED_LISTEN_ONLY",
    "EVENT_RESTART",
    "Failure",
    "KnownRequest",
    "MAX_EVENTS",
    "MasterEvent",
    "MasterMachine",
    "MasterMachineError",
    "MasterState",
    "NEGATIVE_ACKNOWLEDGE",
    "Outcome",
    "OutcomeKind",
    "RetryPolicy",
    "SAFE_TO_REPEAT",
    "SerialLineCounters",
    "SkipReason",
    "SlaveEvent",
    "SlaveMachine",
    "SlaveMachineError",
    "SlaveState",
    "Transaction",
    "TransitionObserver",
    "frame_error_from_discard",
    "receive_event",
    "send_event",
    "state_diagram",
)

publish(__name__, __all__, globals())
