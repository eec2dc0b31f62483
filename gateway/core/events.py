"""The news the gateway has for the control socket's subscribers, as typed data.

Pure data -- frozen dataclasses, no I/O, no clock, no format.  The control cycle puts them in
its outbox (:class:`gateway.runtime.publish.Publisher`: an error as it is reported, the
odometry and the state at their rates); the daemon hands each to the clients subscribed to
its topic, in the JSON form of :mod:`gateway.wire.socket.events` (the model kept apart from
its format, as :mod:`gateway.core.status` is from :mod:`gateway.wire.socket.status`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, TypeAlias

from gateway.core.status import LastError

if TYPE_CHECKING:
    from gateway.core.kinematics.odometry import OdometryState
    from gateway.core.types import GatewayState

__all__ = ["OdometryEvent", "OutboxEvent", "StatusEvent"]


@dataclass(frozen=True, slots=True)
class OdometryEvent:
    """The odometry, at the odometry rate.

    :param state: the pose, the body twist and the rest of the odometry's state.
    """

    state: OdometryState


@dataclass(frozen=True, slots=True)
class StatusEvent:
    """The gateway's state, at the status rate.

    :param state: what the gateway as a whole is doing.
    :param reason: why it is in FAULT or ESTOP (empty otherwise).
    """

    state: GatewayState
    reason: str


#: Anything the outbox holds: an error the gateway reported (on CAN as ``WG_Error`` too; the
#: status model's :class:`~gateway.core.status.LastError`, the same news ``status`` keeps),
#: the odometry or the state.
OutboxEvent: TypeAlias = LastError | OdometryEvent | StatusEvent
