"""The vocabulary of the control socket: ops, topics, request types and :class:`ProtocolError`.

Also the small helpers that render a received value for an error message, shared by the
parser and the reply builder.  Pure: no I/O, no clock.
"""

from __future__ import annotations

import enum
import json
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, TypeAlias

from gateway.core.errors import GatewayError
from gateway.core.kinematics.odometry import Pose

if TYPE_CHECKING:
    from collections.abc import Iterable

    from gateway.core.types import Twist

#: Longest accepted message in bytes, newline excluded: the protocol's ceiling.
MAX_MESSAGE_BYTES = 4096
#: The control server's default line limit, newline excluded.  The longest request
#: ``json.dumps`` writes is 899 bytes (``reset_odometry`` with three 17-digit floats and a
#: 64-character id of astral-plane characters, each escaped as two ``\uXXXX``); a typical one is
#: under 100.  Only padding makes one longer: extra whitespace, long-winded numbers, a topic
#: repeated.
MAX_REQUEST_BYTES = 1024
#: Longest accepted string request id, in characters.
MAX_ID_CHARS = 64

#: A request id as it appears on the wire.
RequestId: TypeAlias = int | str

_SHORT_JSON_MAX_CHARS = 40


class Op(str, enum.Enum):
    """The ``"op"`` of a request."""

    TWIST = "twist"
    STOP = "stop"
    ESTOP = "estop"
    ENABLE = "enable"
    DISABLE = "disable"
    STATUS = "status"
    RESET_ODOMETRY = "reset_odometry"
    SUBSCRIBE = "subscribe"
    UNSUBSCRIBE = "unsubscribe"


class Topic(str, enum.Enum):
    """What a client can subscribe to."""

    ODOMETRY = "odometry"
    STATUS = "status"
    #: Faults and refused commands, as they happen.
    ERROR = "error"


class ProtocolError(GatewayError, ValueError):
    """A control-socket message that is not a valid request.

    :param message: names the field, what was expected and what came.
    :param request_id: the request's id when it could be read, else ``None``.
    """

    def __init__(self, message: str, request_id: RequestId | None = None) -> None:
        super().__init__(message)
        self.request_id = request_id


@dataclass(frozen=True, slots=True)
class TwistRequest:
    """Follow a body twist.

    :param twist: the commanded twist (each component finite, magnitude at most 100).
    :param id: the request id to echo, ``None`` if absent.
    """

    twist: Twist
    id: RequestId | None = None

    @property
    def op(self) -> Op:
        """Always :attr:`Op.TWIST`."""
        return Op.TWIST


@dataclass(frozen=True, slots=True)
class CommandRequest:
    """A request that takes no argument: stop, estop, enable, disable, status, unsubscribe.

    :param op: which one.
    :param id: the request id to echo, ``None`` if absent.
    """

    op: Op
    id: RequestId | None = None


@dataclass(frozen=True, slots=True)
class ResetOdometryRequest:
    """Set the odometry pose.

    :param pose: the new pose (origin by default; heading wrapped to [-pi, pi)).
    :param id: the request id to echo, ``None`` if absent.
    """

    pose: Pose = field(default_factory=Pose)
    id: RequestId | None = None

    @property
    def op(self) -> Op:
        """Always :attr:`Op.RESET_ODOMETRY`."""
        return Op.RESET_ODOMETRY


@dataclass(frozen=True, slots=True)
class SubscribeRequest:
    """Receive events of some topics on this connection.

    :param topics: the topics (at least one).
    :param id: the request id to echo, ``None`` if absent.
    """

    topics: frozenset[Topic]
    id: RequestId | None = None

    @property
    def op(self) -> Op:
        """Always :attr:`Op.SUBSCRIBE`."""
        return Op.SUBSCRIBE


#: Any parsed request.
Request: TypeAlias = TwistRequest | CommandRequest | ResetOdometryRequest | SubscribeRequest


def short_json(value: object) -> str:
    """A short JSON rendering of a received value for error messages."""
    try:
        text = json.dumps(value, ensure_ascii=False)
    except (TypeError, ValueError):  # not from json.loads; be safe anyway
        text = repr(value)
    return text if len(text) <= _SHORT_JSON_MAX_CHARS else text[: _SHORT_JSON_MAX_CHARS - 3] + "..."


def json_type(value: object) -> str:
    """The JSON type of a value parsed by :func:`json.loads`, as error messages name it."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "an array"
    return "an object"


def quoted(names: Iterable[str]) -> str:
    """Names in double quotes, comma-separated."""
    return ", ".join(f'"{n}"' for n in names)
