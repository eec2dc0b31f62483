"""The gateway's state machine as a table: which event takes which state where.

:class:`~gateway.core.control.Supervisor` changes its
:class:`~gateway.core.types.GatewayState` in one place, which looks the (state, event) pair up
in :data:`TRANSITIONS` (the state it goes to) and :data:`IGNORED` (events that leave a state
as it is, doing nothing: an enable while running, a disable while an e-stop is latched); any
other pair raises :class:`~gateway.core.errors.IllegalTransitionError`.  The drivers keep
their drives' state changes the same way (the ODrive axis-state table,
``drivers.odrive.messages.TRANSITIONS``).

The table, by event (``*``: from every state)::

    ENABLE          DISABLED, FAULT, ESTOP -> ENABLING   (ignored in ENABLING, RUNNING, STOPPING)
    RETRY           FAULT -> ENABLING                    (automatic recovery)
    ENABLED         ENABLING -> RUNNING                  (every motor reports enabled)
    FAULT           ENABLING, RUNNING -> FAULT           (a motor faulted, fell silent, left its
                                                          command, or did not enable in time)
    ENABLE_REFUSED  * -> FAULT                           (see below)
    COMMAND_FAILED  * -> FAULT                           (a command could not be encoded)
    BUS_FAULT       ENABLING, RUNNING -> FAULT           (ignored elsewhere)
    ESTOP           * -> ESTOP
    DISABLE         DISABLED, ENABLING, RUNNING, FAULT -> DISABLED   (ignored in ESTOP, STOPPING)
    SHUTDOWN        * -> STOPPING

``ENABLE_REFUSED`` comes from the loop, which takes an enable request in the cycle after it
was made (it sends the drives' enable frames then): an e-stop, a disable or a shutdown in
between withdraws the request; a fault or every motor reporting enabled does not, so the
drives' refusal can come in FAULT or RUNNING too (the table takes it in any state).
"""

from __future__ import annotations

import enum
from types import MappingProxyType
from typing import TYPE_CHECKING, TypeAlias

from gateway.core.errors import IllegalTransitionError
from gateway.core.types import GatewayState

if TYPE_CHECKING:
    from collections.abc import Mapping

__all__ = ["IGNORED", "TRANSITIONS", "Event", "next_state"]


class Event(enum.Enum):
    """What can change the gateway's state (see the module's table)."""

    #: An enable request (control socket, the CAN ENABLE flag).
    ENABLE = "enable"
    #: The automatic re-enable after a fault, once every motor answers again.
    RETRY = "retry"
    #: Every motor reports enabled.
    ENABLED = "enabled"
    #: A motor faulted, stopped answering, left its command, or did not enable in time.
    FAULT = "fault"
    #: The drives refused the enable sequence.
    ENABLE_REFUSED = "enable refused"
    #: A drive could not encode the cycle's command.
    COMMAND_FAILED = "command failed"
    #: The bus cannot carry the commands (bus-off, a command that does not go out).
    BUS_FAULT = "bus fault"
    #: An e-stop (socket, CAN, the latch at start-up).
    ESTOP = "e-stop"
    #: A disable request.
    DISABLE = "disable"
    #: The process is stopping.
    SHUTDOWN = "shutdown"


#: One row per event: the states it leaves, the state it goes to, the states it is ignored in.
_Row: TypeAlias = tuple[Event, tuple[GatewayState, ...], GatewayState, tuple[GatewayState, ...]]


def _rows() -> list[_Row]:
    d, en, run = GatewayState.DISABLED, GatewayState.ENABLING, GatewayState.RUNNING
    fault, estop, stop = GatewayState.FAULT, GatewayState.ESTOP, GatewayState.STOPPING
    every = tuple(GatewayState)
    return [
        (Event.ENABLE, (d, fault, estop), en, (en, run, stop)),
        (Event.RETRY, (fault,), en, ()),
        (Event.ENABLED, (en,), run, ()),
        (Event.FAULT, (en, run), fault, ()),
        (Event.ENABLE_REFUSED, every, fault, ()),
        (Event.COMMAND_FAILED, every, fault, ()),
        (Event.BUS_FAULT, (en, run), fault, (d, fault, estop, stop)),
        (Event.ESTOP, every, estop, ()),
        (Event.DISABLE, (d, en, run, fault), d, (estop, stop)),
        (Event.SHUTDOWN, every, stop, ()),
    ]


#: (current state, event) -> the state it goes to.
TRANSITIONS: Mapping[tuple[GatewayState, Event], GatewayState] = MappingProxyType(
    {(s, event): target for event, sources, target, _ in _rows() for s in sources}
)
#: (current state, event) pairs that leave the state as it is and do nothing else.
IGNORED: frozenset[tuple[GatewayState, Event]] = frozenset(
    (s, event) for event, _, _, left in _rows() for s in left
)


def next_state(state: GatewayState, event: Event) -> GatewayState | None:
    """The state ``event`` takes ``state`` to; ``None`` when the table ignores it there.

    :raises IllegalTransitionError: for a pair that is in neither table.
    """
    target = TRANSITIONS.get((state, event))
    if target is not None or (state, event) in IGNORED:
        return target
    allowed = sorted(s.name for s, e in TRANSITIONS if e is event)
    raise IllegalTransitionError(
        f"gateway state machine: expected the event {event.value!r} in "
        f"{' or '.join(allowed)}, but the gateway is {state.name}"
    )
