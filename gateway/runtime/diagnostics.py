"""The gateway's status as ROS 2 diagnostics: one ``diagnostic_msgs/msg/DiagnosticArray``.

What ROS's diagnostic tools (``diagnostic_aggregator``, ``rqt_robot_monitor``) show for a
hardware driver, from the status model that ``wheelgate status`` prints
(:class:`~gateway.core.status.GatewayStatus`), one :class:`DiagnosticStatus` for each of:

* ``<node>: gateway``, the gateway as a whole: OK while DISABLED, ENABLING or RUNNING, WARN in
  ESTOP or STOPPING, ERROR in FAULT (the message says the state and its reason); the target and
  last command, the loop's timing, the last error and the configuration as values;
* ``<node>: CAN bus``: ERROR when frames do not go out or the CAN controller is bus-off, WARN
  when it is error-passive or past its warning limit (ISO 11898-1 clause 12), else OK;
* ``<node>: motor <name>`` for every drive motor and steering actuator, its hardware id the
  driver, node ID and bus: ERROR for a controller in fault or silent (the gateway then stops
  the robot) and for a controller-side stop that could not be configured, WARN for one whose
  stop is not known (a DJI ESC has none, a DBC controller's was not stated), else OK.

The names follow ``diagnostic_updater``'s custom (``"<node name>: <task>"``), so an aggregator's
analyzer can gather them by their prefix: the bridge's ROS node name, the robot's name in the
Foxglove live view.  Pure: no I/O, no clock.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from gateway.core.protection import Guard, ProtectionState, stop_text
from gateway.core.status import BusErrorState, fault_names, state_name
from gateway.core.types import DriveState, GatewayState
from gateway.wire.ros2 import (
    DiagnosticArray,
    DiagnosticLevel,
    DiagnosticStatus,
    Header,
    KeyValue,
    ns_to_stamp,
)

if TYPE_CHECKING:
    from collections.abc import Mapping

    from gateway.core.settings import GatewayConfig
    from gateway.core.status import BusReport, GatewayStatus, MotorReport
    from gateway.core.types import Twist

__all__ = ["diagnostic_array", "hardware_ids"]

_GATEWAY_LEVEL = {GatewayState.FAULT: DiagnosticLevel.ERROR,
                  GatewayState.ESTOP: DiagnosticLevel.WARN,
                  GatewayState.STOPPING: DiagnosticLevel.WARN}
_BUS_LEVEL = {BusErrorState.BUS_OFF: DiagnosticLevel.ERROR,
              BusErrorState.PASSIVE: DiagnosticLevel.WARN,
              BusErrorState.WARNING: DiagnosticLevel.WARN}
#: A value not known yet (a motor not heard, a stop of unknown timeout).
UNKNOWN = "unknown"


def diagnostic_array(status: GatewayStatus, node: str, hardware: Mapping[str, str],
                     stamp_ns: int) -> DiagnosticArray:
    """The diagnostics of ``status`` (see the module's doc).

    :param node: the ROS node's name (the statuses' prefix).
    :param hardware: each motor's hardware id, by its name in the status.
    :param stamp_ns: the report's time, ns since the Unix epoch.
    """
    return DiagnosticArray(Header(ns_to_stamp(stamp_ns), ""), (
        _gateway(status, node), _bus(status.bus, status.counters.events, node),
        *(_motor(m, f"{node}: motor {m.name}", hardware.get(m.name, "")) for m in status.motors),
    ))


def hardware_ids(config: GatewayConfig) -> dict[str, str]:
    """Each motor's hardware id, by its name in the status: ``odrive node 3 on socketcan:can0``
    (drive motors and steering actuators)."""
    bus = f"{config.bus.interface}:{config.bus.channel}"
    return {m.wheel: f"{m.driver} node {m.node_id} on {bus}"
            for m in (*config.motors, *config.steering) if m is not None}


def _number(value: float | None, unit: str = "") -> str:
    return UNKNOWN if value is None else f"{value:.6g}" + (f" {unit}" if unit else "")


def _twist(t: Twist) -> str:
    return f"vx {t.vx_m_s:.6g} m/s, vy {t.vy_m_s:.6g} m/s, wz {t.wz_rad_s:.6g} rad/s"


def _gateway(s: GatewayStatus, node: str) -> DiagnosticStatus:
    t, c = s.timing, s.command
    values = [
        KeyValue("state", state_name(s.state)),
        KeyValue("reason", s.reason),
        KeyValue("target", _twist(c.target)),
        KeyValue("command", _twist(c.applied)),
        KeyValue("command timeout active", str(c.cmd_timeout_active).lower()),
        KeyValue("speed limit scale", f"{c.speed_scale:.6g}"),
        KeyValue("loop rate", f"{t.achieved_hz:.1f} Hz of {t.rate_hz:g} Hz"),
        KeyValue("cycles", str(t.cycles)),
        KeyValue("missed deadlines", str(t.missed)),
        KeyValue("lateness p99", f"{t.lateness_p99_us:.0f} us"),
        KeyValue("cycle cost p99", f"{t.cost_p99_us:.0f} us"),
        KeyValue("last error", "" if s.last_error is None else s.last_error.message),
    ]
    if s.config is not None:
        values.append(KeyValue("configuration",
                               f"{s.config.path} (CRC-32 {s.config.fingerprint})"))
    message = state_name(s.state) + (f": {s.reason}" if s.reason else "")
    return DiagnosticStatus(_GATEWAY_LEVEL.get(s.state, DiagnosticLevel.OK), f"{node}: gateway",
                            message, s.robot, tuple(values))


def _bus(bus: BusReport, events: Mapping[str, int], node: str) -> DiagnosticStatus:
    health = bus.health
    values = [KeyValue("interface", bus.interface), KeyValue("channel", bus.channel),
              KeyValue("bitrate", f"{bus.bitrate} bit/s")]
    values += [KeyValue(key.replace("_", " "), str(events.get(key, 0))) for key in (
        "frames_sent", "frames_received", "frames_unsent", "send_failures", "bus_reopens")]
    if health is None:
        level, message = DiagnosticLevel.OK, "health not reported"
    else:
        level = _BUS_LEVEL.get(health.error_state, DiagnosticLevel.OK)
        message = f"controller {health.error_state.value.replace('_', '-')}"
        if not health.healthy:
            level, message = DiagnosticLevel.ERROR, message + "; frames do not go out"
        values += [KeyValue("controller state", health.error_state.value),
                   KeyValue("error frames", str(health.error_frames.get("error_frames", 0))),
                   KeyValue("last error frame", health.last_error_frame)]
    return DiagnosticStatus(level, f"{node}: CAN bus", message,
                            f"{bus.interface}:{bus.channel}", tuple(values))


def _motor(m: MotorReport, name: str, hardware_id: str) -> DiagnosticStatus:
    faults = ", ".join(fault_names(m.faults))
    age = m.feedback_age_s
    stop = m.controller_stop
    if m.state is DriveState.FAULT:
        level = DiagnosticLevel.ERROR
        why = "; ".join(x for x in (faults, m.detail) if x)
        message = f"fault: {why}" if why else "fault"
    elif m.state is DriveState.OFFLINE:
        level = DiagnosticLevel.ERROR
        message = ("offline: no feedback yet" if age is None else
                   f"offline: no feedback for {age:.3g} s")
    elif stop is not None and stop.state is ProtectionState.FAILED:
        level = DiagnosticLevel.ERROR
        message = (f"{state_name(m.state)}; its controller-side stop could not be configured: "
                   f"it will not stop by itself if wheelgate dies")
    elif stop is not None and stop.guard in (Guard.NONE, Guard.UNSTATED):
        level = DiagnosticLevel.WARN
        message = (f"{state_name(m.state)}; no known controller-side stop: it may keep "
                   f"running if wheelgate dies")
    else:
        level, message = DiagnosticLevel.OK, state_name(m.state)
    values = (
        KeyValue("state", state_name(m.state)),
        KeyValue("node id", str(m.node_id)),
        KeyValue("faults", faults),
        KeyValue("detail", m.detail),
        KeyValue("feedback age", _number(None if age is None else age * 1000.0, "ms")),
        KeyValue("position", _number(m.position_rad, "rad")),
        KeyValue("velocity", _number(m.velocity_rad_s, "rad/s")),
        KeyValue("controller stop", UNKNOWN if stop is None else
                 stop_text(stop.guard, stop.timeout_s, stop.state)),
    )
    return DiagnosticStatus(level, name, message, hardware_id, values)
