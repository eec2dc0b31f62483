"""wheelgate's own Zenoh keys: the control socket's messages over the network.

Under ``wheelgate/<namespace>/`` (the ``bridge.namespace``, else the robot's name):

============================  ==========  ===================================================
key                           kind        payload
============================  ==========  ===================================================
``cmd/twist``                 subscribed  a twist request, exactly as on the socket:
                                          ``{"op": "twist", "vx": 0.2, "vy": 0, "wz": 0.1}``;
                                          attachment: the commander's name (optional)
``rpc/<op>``                  queryable   ``<op>`` one of :data:`RPC_OPS`; the query's payload
                                          is the socket's request (empty: ``{"op": <op>}``),
                                          the reply the socket's reply line
``odom``, ``status``,         published   the socket's event lines (``{"event": "odometry",
``error``                                 ...}``)
``gateway``                   token       alive while the gateway runs
``commander/<name>``          token       held by a commander: when the one whose twist the
                                          robot follows disappears, the deadman acts
============================  ==========  ===================================================

Pure: key names and parsing, no Zenoh.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass

from gateway.wire.socket import (
    CommandRequest,
    Op,
    ProtocolError,
    Request,
    ResetOdometryRequest,
    TwistRequest,
    parse_request,
)

__all__ = [
    "COMMANDER_MAX_CHARS",
    "RPC_OPS",
    "NativeKeys",
    "commander_of",
    "parse_query",
    "parse_twist_sample",
]

#: The requests answered as queries.
RPC_OPS: tuple[Op, ...] = (Op.STATUS, Op.STOP, Op.ESTOP, Op.ENABLE, Op.DISABLE,
                           Op.RESET_ODOMETRY, Op.TWIST)
#: Longest commander name (characters).
COMMANDER_MAX_CHARS = 64
_NAME = re.compile(r"^[A-Za-z0-9_.-]+$")


@dataclass(frozen=True, slots=True)
class NativeKeys:
    """The key expressions of one robot.

    :param root: ``wheelgate/<namespace>``.
    """

    root: str

    @classmethod
    def of(cls, namespace: str) -> NativeKeys:
        """The keys under ``wheelgate/<namespace>``."""
        return cls(f"wheelgate/{namespace}")

    @property
    def twist(self) -> str:
        return f"{self.root}/cmd/twist"

    def rpc(self, op: Op) -> str:
        return f"{self.root}/rpc/{op.value}"

    @property
    def odom(self) -> str:
        return f"{self.root}/odom"

    @property
    def status(self) -> str:
        return f"{self.root}/status"

    @property
    def error(self) -> str:
        return f"{self.root}/error"

    @property
    def gateway_token(self) -> str:
        return f"{self.root}/gateway"

    def commander_token(self, name: str) -> str:
        return f"{self.root}/commander/{name}"

    @property
    def commanders(self) -> str:
        """Every commander's token (a key expression with ``*``)."""
        return f"{self.root}/commander/*"


def commander_of(attachment: bytes | None, where: str) -> str | None:
    """The commander named by a twist sample's attachment (``None``: none attached).

    :raises ProtocolError: for a name that is not UTF-8 letters, digits, ``_ . -`` of at most
        :data:`COMMANDER_MAX_CHARS` characters.
    """
    if attachment is None:
        return None
    try:
        name = attachment.decode("utf-8")
    except UnicodeDecodeError:
        raise ProtocolError(f"{where}: attachment: expected a commander name in UTF-8, got "
                            f"{attachment[:20]!r}") from None
    if not (0 < len(name) <= COMMANDER_MAX_CHARS and _NAME.match(name)):
        raise ProtocolError(
            f"{where}: attachment: expected a commander name of 1 to {COMMANDER_MAX_CHARS} "
            f"letters, digits, '_', '.' or '-', got {name[:COMMANDER_MAX_CHARS + 1]!r}"
        )
    return name


def parse_twist_sample(payload: bytes, key: str) -> TwistRequest:
    """A twist published on ``cmd/twist``.

    :raises ProtocolError: as the socket's parser, or for a request other than a twist.
    """
    request = parse_request(payload)
    if not isinstance(request, TwistRequest):
        raise ProtocolError(f"{key}: expected op 'twist', got {request_op(request).value!r}",
                            request.id)
    return request


def parse_query(op: Op, payload: bytes | None, key: str) -> Request:
    """The request of a query on ``rpc/<op>`` (an empty payload is ``{"op": <op>}``).

    :raises ProtocolError: as the socket's parser, or for a request of another op.
    """
    if not payload:
        payload = json.dumps({"op": op.value}).encode()
    request = parse_request(payload)
    got = request_op(request)
    if got is not op:
        raise ProtocolError(f"{key}: expected op {op.value!r}, got {got.value!r}", request.id)
    return request


def request_op(request: Request) -> Op:
    """The op of a parsed request."""
    if isinstance(request, CommandRequest):
        return request.op
    if isinstance(request, TwistRequest):
        return Op.TWIST
    if isinstance(request, ResetOdometryRequest):
        return Op.RESET_ODOMETRY
    return Op.SUBSCRIBE
