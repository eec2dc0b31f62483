"""What the bridge's callbacks hand the loop: requests and the commanders' comings and goings.

Kept apart from :mod:`gateway.runtime.bridge.bridge` (and Zenoh) so that the daemon's side
(:mod:`gateway.runtime.remote`) can tell them apart without loading the bridge.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from gateway.wire.socket import ProtocolError, Request

__all__ = ["NO_REPLY", "CommanderEvent", "Inbound"]

#: Client id of a twist published on ``cmd/twist`` (no reply goes back).
NO_REPLY = 0


@dataclass(frozen=True, slots=True)
class Inbound:
    """A request from the network.

    :param client: where the reply goes (:data:`NO_REPLY` for a published twist).
    :param request: the parsed request, or why it did not parse.
    :param commander: the commander that sent it, if it said.
    """

    client: int
    request: Request | ProtocolError
    commander: str | None = None


@dataclass(frozen=True, slots=True)
class CommanderEvent:
    """A commander's liveliness token appeared (``alive``) or disappeared."""

    commander: str
    alive: bool
