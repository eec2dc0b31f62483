"""The deadman across the network: which commander the robot follows, and what its loss does.

A commander (a teleop, a planner, a fleet manager) may hold a liveliness token: Zenoh removes it
when the commander's session closes, crashes (about 5 ms after a SIGKILL, the TCP connection
drops) or falls silent for longer than the lease (a frozen process, an unplugged cable).  When
the token of the commander whose twist the robot is following disappears, the target goes to
zero at once (``deadman: stop``: within the deceleration limits) or the robot is e-stopped
(``deadman: estop``).  "Following" is exact: the supervisor's target is the very twist that
commander sent last (a newer twist from anyone else, a stop or the command timeout replaced it
otherwise, and the loss changes nothing).

Pure: no Zenoh, no clock.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from gateway.core.types import Twist

__all__ = ["Deadman"]


class Deadman:
    """The twists each commander had accepted last (see the module's doc)."""

    def __init__(self) -> None:
        self._followed: dict[str, Twist] = {}

    def accepted(self, commander: str, twist: Twist) -> None:
        """``commander``'s twist became the target (the object the supervisor holds)."""
        self._followed[commander] = twist

    def lost(self, commander: str, target: Twist) -> bool:
        """``commander``'s token disappeared; whether the robot was following it (``target``
        is the supervisor's target now)."""
        followed = self._followed.pop(commander, None)
        return followed is not None and followed is target
