"""Where one CiA 402 node's enable/stop sequence stands (:mod:`drivers.cia402.sequence`), and
which drive states end a stop."""

from __future__ import annotations

import enum

from drivers.cia402.enums import State


class Phase(enum.IntEnum):
    """Where one node's sequence stands."""

    #: Nothing under way (never enabled, or stopped).
    IDLE = 0
    #: NMT and SDO configuration steps.
    CONFIGURING = 1
    #: NMT start sent; waiting for the first statusword TPDO.
    AWAIT_STATUS = 2
    #: Controlword steps toward OPERATION ENABLED.
    WALKING = 3
    #: OPERATION ENABLED; the driver streams the command RPDO.
    ARMED = 4
    #: Target 0 with ENABLE OPERATION until speed 0, then SHUTDOWN.
    STOPPING = 5
    #: A step failed; :attr:`NodeSequencer.error` says why.  Cleared by the next start.
    FAILED = 6


#: States in which the power stage is off: a stop is complete.
STOPPED = frozenset({State.NOT_READY_TO_SWITCH_ON, State.SWITCH_ON_DISABLED,
                      State.READY_TO_SWITCH_ON, State.FAULT_REACTION_ACTIVE, State.FAULT})
#: Where a stop goes from each operating state.
STOP_TARGET = {State.OPERATION_ENABLED: State.READY_TO_SWITCH_ON,
                State.SWITCHED_ON: State.READY_TO_SWITCH_ON,
                State.QUICK_STOP_ACTIVE: State.SWITCH_ON_DISABLED}
