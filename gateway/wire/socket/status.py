"""The JSON form of the gateway's status (:class:`gateway.core.status.GatewayStatus`): the
payload of a ``status`` reply, and what ``wheelgate status --json`` prints.

:func:`status_to_json` writes it (:mod:`gateway.wire.socket.status_write`);
:func:`status_from_json` reads it back into the model
(:mod:`gateway.wire.socket.status_read`) and raises :class:`~gateway.wire.socket.ProtocolError`
for a malformed one, naming the key (as a path, ``status.motors[1].node_id``), what was expected
and what came.  Pure: no I/O, no clock.

The payload, key by key (a reply adds ``"ok"`` and ``"id"``, which the reader skips)::

    robot, reason        strings
    state                the GatewayState's lower-case name ("running")
    command              {"target": twist, "applied": twist, "cmd_timeout_active": bool,
                          "speed_scale", "accel_scale"}; a twist is {"vx_m_s", "vy_m_s",
                          "wz_rad_s"}
    motors               [{"name", "node_id", "state" (lower-case DriveState name), "faults"
                          (lower-case DriveFault names), "detail", "feedback_age_s",
                          "position_rad", "velocity_rad_s" (null: no feedback yet),
                          "controller_stop": {"guard", "timeout_s", "state"} or null}]
    tracking             {"tolerance_rad_s", "tolerance_ratio", "time_s", "steer_tolerance_rad",
                          "worst_ratio", "steer_worst_ratio"}
    odometry             {"x", "y", "theta", "vx", "vy", "wz", "slip", "distance", "t"}
    counters             {<event>: n, ..., "rejected_frames": {<driver class>: {<reason>: n}},
                          "commands_not_followed": {<driver class>: {<kind>: n}}}
    socket               {"path", <the ServerCounters fields>}
    timing               {<the TimingReport fields>}
    last_error           {"code" (lower-case ErrorCode name), "message"} or null
    realtime             [string, ...]
    bus                  {"interface", "channel", "bitrate", "healthy", "error_state",
                          "error_frames": {<class>: n}, "last_error_frame", "bits", "time_s",
                          "frames": [{"id", "extended", "direction" ("rx"/"tx"), "count"}]}

Numbers follow the protocol's rule (:mod:`gateway.wire.socket`): a float that is not finite is
written ``null``; read back, ``null`` is NaN where the model needs a number and ``None`` where it
allows one.  Integers stay integers, so a reply read and written again is the same JSON.

Keys that daemons from before their introduction did not send may be absent: ``tracking`` and
the bus's health (``healthy``, ``error_state``, ``error_frames``, ``last_error_frame``) read as
``None`` and are then not written; ``controller_stop`` reads as ``None``; the late-start
counters, ``steer_worst_ratio`` and the socket's counters as 0; ``burst_gap_max_ms`` as ``None``
(not written); ``rejected_frames`` and ``commands_not_followed`` as empty.  Keys the reader
does not know are skipped (those of newer daemons).
"""

from __future__ import annotations

from gateway.wire.socket.status_read import status_from_json
from gateway.wire.socket.status_write import odometry_to_json, status_to_json

__all__ = ["odometry_to_json", "status_from_json", "status_to_json"]
