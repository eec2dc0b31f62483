"""The motors' stop when the daemon shuts down (:meth:`gateway.runtime.daemon.Daemon.shutdown`).

Every motor gets its zero and disarm, then the drives are polled for :data:`SHUTDOWN_GRACE_S`
so that a multi-step disarm (a CiA 402 state machine walked down, an ODrive read back)
finishes.  Not when the gateway has not armed its motors and another program commands them,
or it has not yet listened for one (:meth:`gateway.runtime.commanders.Commanders.quiet`):
a stop from here would stop the other's robot too, so nothing is sent.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.core.errors import GatewayError

if TYPE_CHECKING:
    from gateway.runtime.loop import Gateway

log = logging.getLogger(__name__)

#: How long the shutdown keeps polling so multi-step disarm sequences finish (s).
SHUTDOWN_GRACE_S = 0.3


@dataclass(frozen=True, slots=True)
class Stopped:
    """What the shutdown sent the motors.

    :param sent: every motor's zero and disarm went out (the bus took every frame of it, and
        every driver could build one).
    :param left_to: why nothing was sent ('' when the stop was sent).
    """

    sent: bool
    left_to: str = ""


def stop_motors(gw: Gateway, now_s: float) -> Stopped:
    """Send every motor its zero and disarm at ``now_s``, then poll for the grace time (an
    error of a driver's poll then is logged: the stop went out first)."""
    if not gw.armed and gw.commanders.quiet(now_s):
        holder = gw.commanders.holder(now_s)
        why = (f"another program commands them ({holder})" if holder else
               "it stopped before it had listened for another commander")
        log.warning("nothing sent to the motors on stopping: %s", why)
        return Stopped(False, why)
    if not (sent := gw.edge.send(gw.drives.disable(now_s))):  # (run's last line says)
        log.error("the zero and disarm did not all go out: the bus refused them")
    end = time.monotonic() + SHUTDOWN_GRACE_S
    try:
        while time.monotonic() < end:
            time.sleep(0.01)
            t = time.monotonic()
            for frame in gw.edge.receive(t):
                gw.drives.on_frame(frame)
            gw.edge.send(gw.drives.poll(t))
    except GatewayError as err:  # (the stop went out first)
        log.error("shutdown after the stop: %s", err)
    return Stopped(sent and not gw.drives.unstopped)
