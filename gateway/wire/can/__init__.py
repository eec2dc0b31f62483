"""wheelgate's own CAN messages: a pure codec, no I/O, no clock.

The published description is ``config/wheelgate.dbc`` (cantools and other DBC tools read the
traffic with it); ``tests/wire/test_wgproto_messages.py`` proves that this hand-written
``struct`` codec and cantools agree on every message, both ways.  Every payload is little
endian with DLC 8:

====================  =====  ===========================================================
message               ID     payload (i: signed, u: unsigned, bits)
====================  =====  ===========================================================
``WG_Twist_Cmd``      0x100  vx, vy i16 mm/s; wz i16 mrad/s; counter u8; flags u8
``WG_Odom_Pose``      0x101  x, y i24 mm (wrapping); theta i16 in 0.1 mrad
``WG_Odom_Velocity``  0x102  vx, vy i16 mm/s; wz i16 mrad/s; slip u16 mm/s
``WG_Status``         0x103  state, faulted motors, counter, flags u8; two u16 counts
``WG_Error``          0x104  code, wheel, constraint, twist counter u8; residual, count u16
====================  =====  ===========================================================

Twist commands come from other devices, so :meth:`WgCodec.encode_twist` raises
:class:`~gateway.core.errors.EncodeError` for a value it cannot send, and
:meth:`WgCodec.decode_twist`
raises :class:`~gateway.core.errors.DecodeError` for a malformed frame.  Everything the gateway
sends (odometry, status, error) comes from the control loop, which must never fail on its
output path: those encoders saturate instead of raising (NaN speeds encode as 0; a NaN or huge
slip or residual as the maximum, "at least this much").  Pose x and y wrap modulo 2**24 mm
(16777.216 m) on the wire; :func:`unwrap_position_m` undoes it on the receiving side.  The
error ``count`` wraps modulo 65536 (a sequence number), the status counts saturate.

* :mod:`gateway.wire.can.messages`: scales, message names, flag enums, :class:`CanIds` and the
  decoded forms of the messages.
* :mod:`gateway.wire.can.codec`: :class:`WgCodec`, the ``struct`` layouts, and
  :func:`unwrap_position_m`.
* :mod:`gateway.wire.can.counter`: :class:`CounterTracker`, the ``WG_Twist_Cmd`` counter logic.
"""

from __future__ import annotations

from gateway.core.can_ids import ID_KEYS, CanIds
from gateway.wire.can.codec import WgCodec, unwrap_position_m
from gateway.wire.can.counter import CounterKind, CounterTracker, classify_counter
from gateway.wire.can.messages import (
    ANGLE_SCALE,
    DLC,
    ERROR,
    I16_MAX,
    I16_MIN,
    NO_TWIST_COUNTER,
    NO_WHEEL,
    ODOM_POSE,
    ODOM_VELOCITY,
    POSITION_SCALE,
    POSITION_WRAP_M,
    SPEED_SCALE,
    STATUS,
    TWIST_CMD,
    U8_MAX,
    U16_MAX,
    ErrorReport,
    OdomVelocity,
    StatusFlags,
    StatusReport,
    TwistCommand,
    TwistFlags,
    WgMessage,
)

__all__ = [
    "ANGLE_SCALE",
    "DLC",
    "ERROR",
    "I16_MAX",
    "I16_MIN",
    "ID_KEYS",
    "NO_TWIST_COUNTER",
    "NO_WHEEL",
    "ODOM_POSE",
    "ODOM_VELOCITY",
    "POSITION_SCALE",
    "POSITION_WRAP_M",
    "SPEED_SCALE",
    "STATUS",
    "TWIST_CMD",
    "U8_MAX",
    "U16_MAX",
    "CanIds",
    "CounterKind",
    "CounterTracker",
    "ErrorReport",
    "OdomVelocity",
    "StatusFlags",
    "StatusReport",
    "TwistCommand",
    "TwistFlags",
    "WgCodec",
    "WgMessage",
    "classify_counter",
    "unwrap_position_m",
]
