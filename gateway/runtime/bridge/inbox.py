"""What the bridge's callbacks hand the loop: requests and the commanders' comings and goings.

Kept apart from :mod:`gateway.runtime.bridge.bridge` (and Zenoh) so that the daemon's side
(:mod:`gateway.runtime.remote`) can tell them apart without loading the bridge.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Callable

    from gateway.wire.socket import ProtocolError, Request

__all__ = ["NO_REPLY", "CommanderEvent", "Inbound", "TwistSource"]

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


@dataclass(frozen=True, slots=True)
class TwistSource:
    """Where published twists come in (``cmd/twist``, a ROS ``cmd_vel`` type): a Zenoh
    subscriber whose handler is a ring of one sample, so Zenoh keeps only the newest (newest
    wins, as on the socket) and no Python runs per sample: a flood costs the loop one parse a
    cycle (:meth:`take`).

    :param subscriber: the subscriber (``try_recv()``: the newest sample since the last call,
        or ``None``).
    :param parse: ``parse(payload, attachment, key)``: the request and its commander; raises
        :class:`~gateway.wire.socket.ProtocolError` naming what was expected and what came.
    """

    subscriber: Any
    parse: Callable[[bytes, bytes | None, str], Inbound]

    def take(self) -> Inbound | None:
        """The newest sample's request (``None``: none came since the last call).

        :raises ProtocolError: as :attr:`parse`.
        """
        sample = self.subscriber.try_recv()
        if sample is None:
            return None
        attachment = sample.attachment
        return self.parse(sample.payload.to_bytes(),
                          None if attachment is None else attachment.to_bytes(),
                          str(sample.key_expr))
