"""``diagnostic_msgs/msg/DiagnosticArray``: what ``/diagnostics`` carries, and its XCDR1 codec.

The messages of the package ``diagnostic_msgs`` in the public repository
ros2/common_interfaces, field for field: an array of :class:`DiagnosticStatus` (a level, the
component's name, a message, a hardware id and :class:`KeyValue` pairs) under a header.  ROS's
``diagnostic_aggregator`` and ``rqt_robot_monitor`` read it on ``/diagnostics``.

====================================  =========================================================
message                               body layout (offsets from the end of the 4-byte header)
====================================  =========================================================
``diagnostic_msgs/msg/DiagnosticArray`` header (i32 sec, u32 nanosec, string frame_id), u32
                                      count, then per status: u8 level, pad to 4, strings
                                      name, message, hardware_id, u32 count, then per value
                                      strings key and value
====================================  =========================================================

The decoder raises :class:`~gateway.core.errors.DecodeError` and nothing else (a level other
than the four is one); the encoder :class:`~gateway.core.errors.EncodeError`.  Pure.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.core.errors import DecodeError, EncodeError
from gateway.wire.ros2.cdr import read_header, write_header
from gateway.wire.ros2.cdr_stream import CdrReader, CdrWriter, Payload

if TYPE_CHECKING:
    from gateway.wire.ros2.messages import Header

__all__ = ["DIAGNOSTIC_ARRAY", "DiagnosticArray", "DiagnosticLevel", "DiagnosticStatus",
           "KeyValue", "decode_diagnostic_array", "encode_diagnostic_array"]

DIAGNOSTIC_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"
#: The fewest body bytes a status takes (level, three empty strings, no values), and a value.
_MIN_STATUS_BYTES = 1 + 3 * 5 + 4
_MIN_VALUE_BYTES = 2 * 5


class DiagnosticLevel(enum.IntEnum):
    """``DiagnosticStatus.level`` (a ``byte`` on the wire), the message's constants."""

    OK = 0
    WARN = 1
    ERROR = 2
    #: No news from the component (the aggregator's verdict on a status that stopped coming).
    STALE = 3


@dataclass(frozen=True, slots=True)
class KeyValue:
    """``diagnostic_msgs/msg/KeyValue``: one labelled value, as text."""

    key: str = ""
    value: str = ""


@dataclass(frozen=True, slots=True)
class DiagnosticStatus:
    """``diagnostic_msgs/msg/DiagnosticStatus``: one component.

    :param level: how it is.
    :param name: the component, ``"<node>: <component>"`` by ``diagnostic_updater``'s custom.
    :param message: its state, for a person.
    :param hardware_id: what identifies the hardware (bus and node ID).
    :param values: what it measured or knows, as text.
    """

    level: DiagnosticLevel = DiagnosticLevel.OK
    name: str = ""
    message: str = ""
    hardware_id: str = ""
    values: tuple[KeyValue, ...] = ()


@dataclass(frozen=True, slots=True)
class DiagnosticArray:
    """``diagnostic_msgs/msg/DiagnosticArray``: the statuses of one report."""

    header: Header
    status: tuple[DiagnosticStatus, ...] = ()


def encode_diagnostic_array(message: DiagnosticArray) -> bytes:
    """The ``diagnostic_msgs/msg/DiagnosticArray`` payload of ``message``."""
    if not isinstance(message, DiagnosticArray) or not isinstance(message.status,
                                                                  (tuple, list)):
        raise EncodeError(f"{DIAGNOSTIC_ARRAY}: expected a DiagnosticArray with a sequence of "
                          f"DiagnosticStatus, got {message!r}")
    w = CdrWriter(DIAGNOSTIC_ARRAY)
    write_header(w, message.header, "header")
    w.sequence_length(len(message.status), "status")
    for i, status in enumerate(message.status):
        where = f"status[{i}]"
        if (not isinstance(status, DiagnosticStatus)
                or not isinstance(status.level, DiagnosticLevel)
                or not isinstance(status.values, (tuple, list))):
            raise EncodeError(f"{DIAGNOSTIC_ARRAY}: expected a DiagnosticStatus with a "
                              f"DiagnosticLevel and a sequence of KeyValue for {where}, got "
                              f"{status!r}")
        w.octet(int(status.level), f"{where}.level")
        w.string(status.name, f"{where}.name")
        w.string(status.message, f"{where}.message")
        w.string(status.hardware_id, f"{where}.hardware_id")
        w.sequence_length(len(status.values), f"{where}.values")
        for j, pair in enumerate(status.values):
            if not isinstance(pair, KeyValue):
                raise EncodeError(f"{DIAGNOSTIC_ARRAY}: expected a KeyValue for "
                                  f"{where}.values[{j}], got {pair!r}")
            w.string(pair.key, f"{where}.values[{j}].key")
            w.string(pair.value, f"{where}.values[{j}].value")
    return w.payload()


def decode_diagnostic_array(payload: Payload) -> DiagnosticArray:
    """The :class:`DiagnosticArray` in a ``diagnostic_msgs/msg/DiagnosticArray`` payload."""
    r = CdrReader(DIAGNOSTIC_ARRAY, payload)
    header = read_header(r, "header")
    statuses = []
    for i in range(r.sequence_length("status", _MIN_STATUS_BYTES)):
        where = f"status[{i}]"
        raw = r.octet(f"{where}.level")
        try:
            level = DiagnosticLevel(raw)
        except ValueError:
            raise DecodeError(f"{DIAGNOSTIC_ARRAY}: expected 0 (OK), 1 (WARN), 2 (ERROR) or 3 "
                              f"(STALE) for {where}.level, got {raw}") from None
        name = r.string(f"{where}.name")
        text = r.string(f"{where}.message")
        hardware_id = r.string(f"{where}.hardware_id")
        values = tuple(
            KeyValue(r.string(f"{where}.values[{j}].key"),
                     r.string(f"{where}.values[{j}].value"))
            for j in range(r.sequence_length(f"{where}.values", _MIN_VALUE_BYTES)))
        statuses.append(DiagnosticStatus(level, name, text, hardware_id, values))
    r.finish()
    return DiagnosticArray(header, tuple(statuses))
