"""Statuses for tests: one written out (:func:`sample_status`) and any (:func:`statuses`, a
hypothesis strategy).  Shared by the tests of the format, the report, ``wheelgate status``,
``jog`` and ``monitor``."""

from __future__ import annotations

import dataclasses
from types import MappingProxyType
from typing import TYPE_CHECKING

from hypothesis import strategies as st

from gateway.core.kinematics.odometry import OdometryState, Pose
from gateway.core.protection import Guard, ProtectionState
from gateway.core.settings import TrackingLimits
from gateway.core.status import (
    BusErrorState,
    BusHealth,
    BusReport,
    CommandReport,
    ConfigReport,
    ControllerStop,
    Counters,
    Direction,
    FrameCount,
    GatewayStatus,
    LastError,
    MotorReport,
    ServerCounters,
    SocketReport,
    TimingReport,
    TrackingReport,
)
from gateway.core.types import DriveFault, DriveState, ErrorCode, GatewayState, Twist

if TYPE_CHECKING:
    import enum
    from collections.abc import Mapping

#: The daemon's event counters, in its order (``Gateway.counts``, then ``Supervisor.counts``).
EVENTS = ("cycles", "frames_sent", "frames_received", "send_failures", "bus_reopens",
          "can_twists", "can_duplicates", "can_lost", "bad_can_twists", "errors_reported",
          "odometry_errors", "receive_failures", "frames_unsent", "partial_bursts", "send_waits",
          "fd_frames_ignored", "infeasible", "projected", "rejected", "faults", "cmd_timeouts",
          "estops")
#: The bus's error frames by class, in the daemon's order.
ERROR_FRAMES = ("error_frames", "tx_timeout", "lost_arbitration", "controller",
                "protocol_violation", "transceiver", "no_ack", "bus_off", "bus_error",
                "restarted")


def _counts(names: tuple[str, ...], **values: int) -> Mapping[str, int]:
    return MappingProxyType({name: values.get(name, 0) for name in names})


def sample_status(**changes: object) -> GatewayStatus:
    """A differential robot, running, one motor faulted, with a bit of everything."""
    status = GatewayStatus(
        robot="tb3",
        state=GatewayState.RUNNING,
        reason="",
        command=CommandReport(Twist(0.2, 0.0, 0.5), Twist(0.1, 0.0, 0.25), False, 0.8, 1.0),
        motors=(
            MotorReport("left", 1, DriveState.ENABLED, DriveFault.NONE, "", 0.002, 1.5, 6.0,
                        ControllerStop(Guard.CONFIGURED, 0.25, ProtectionState.CONFIRMED)),
            MotorReport("right", 2, DriveState.FAULT,
                        DriveFault.OVER_TEMPERATURE | DriveFault.ENCODER, "MOTOR_OVERTEMP",
                        None, None, None,
                        ControllerStop(Guard.NONE, None, ProtectionState.NOT_APPLICABLE)),
        ),
        tracking=TrackingReport(TrackingLimits(1.0, 0.2, 0.5, 0.2), 0.25, 0.0),
        odometry=OdometryState(Pose(1.0, -0.5, 0.25), Twist(0.1, 0.0, 0.25), 0.001, 2.5, 12.5),
        counters=Counters(
            _counts(EVENTS, cycles=2000, frames_sent=4000, frames_received=3900, faults=1),
            MappingProxyType({"OdriveDriver": MappingProxyType({"bad length": 2})}),
            MappingProxyType({"VescDriver": MappingProxyType({"below minimum ERPM": 3})}),
        ),
        socket=SocketReport("/run/wheelgate/wheelgate.sock",
                            ServerCounters(clients=1, accepted=3, malformed=1)),
        timing=TimingReport(2000, 1, 200.0, 199.9, 12.0, 80.0, 120.0, 150.0, 400.0, 700.0, 5,
                            900.0, 1500.0, 1600.0, 1, 0, 0, 8.5),
        last_error=LastError(ErrorCode.MOTOR_FAULT, "motor 'right' (odrive node 2) faulted"),
        realtime=("gc: 100 start-up objects frozen",),
        bus=BusReport("virtual", "wheelgate", 500_000,
                      BusHealth(True, BusErrorState.ACTIVE,
                                _counts(ERROR_FRAMES, error_frames=2, no_ack=2), "no ACK"),
                      123_456, 12.5,
                      (FrameCount(0x21, False, Direction.RX, 10),
                       FrameCount(0x21, False, Direction.TX, 11),
                       FrameCount(0x18FF0013, True, Direction.TX, 3))),
        config=ConfigReport("/etc/wheelgate/robot.yaml", "1c291ca3"),
    )
    return dataclasses.replace(status, **changes)  # type: ignore[arg-type]


# --------------------------------------------------------------------- any status

_names = st.text(st.characters(codec="utf-8"), max_size=12)
_floats = st.floats(allow_nan=False, allow_infinity=False, width=64)
_numbers = _floats | st.integers(-(2**53), 2**53)
_counts_st = st.integers(0, 2**63 - 1)
_maybe = st.none() | _floats


def _enum(kind: type[enum.Enum]) -> st.SearchStrategy[enum.Enum]:
    return st.sampled_from(list(kind))


def _mapping(keys: st.SearchStrategy[str], values: st.SearchStrategy[object]
             ) -> st.SearchStrategy[Mapping[str, object]]:
    return st.dictionaries(keys, values, max_size=4).map(MappingProxyType)


_twists = st.builds(Twist, _numbers, _numbers, _numbers)
_faults = st.lists(st.sampled_from([f for f in DriveFault if f.value]), max_size=3).map(
    lambda fs: DriveFault(sum({f.value for f in fs})))
_stops = st.none() | st.builds(ControllerStop, _enum(Guard), _maybe, _enum(ProtectionState))
_motors = st.builds(MotorReport, _names, st.integers(0, 2**31), _enum(DriveState), _faults,
                    _names, _maybe, _maybe, _maybe, _stops)
_tracking = st.none() | st.builds(
    TrackingReport, st.builds(TrackingLimits, _numbers, _numbers, _numbers, _numbers),
    _numbers, _numbers)
_odometry = st.builds(OdometryState, st.builds(Pose, _numbers, _numbers, _numbers), _twists,
                      _numbers, _numbers, _numbers)
_events = _mapping(_names.filter(lambda k: k not in ("rejected_frames",
                                                     "commands_not_followed")), _counts_st)
_by_driver = _mapping(_names, _mapping(_names, _counts_st))
_timing = st.builds(
    TimingReport, _counts_st, _counts_st, _numbers, _numbers, _numbers, _numbers, _numbers,
    _numbers, _numbers, _numbers, _counts_st, _numbers, _numbers, _numbers, _counts_st,
    _counts_st, _counts_st, st.none() | _numbers)
_health = st.none() | st.builds(BusHealth, st.booleans(), _enum(BusErrorState),
                                _mapping(_names, _counts_st), _names)
_frames = st.lists(st.builds(FrameCount, st.integers(0, 0x1FFFFFFF), st.booleans(),
                             _enum(Direction), _counts_st), max_size=4).map(tuple)


def statuses() -> st.SearchStrategy[GatewayStatus]:
    """Any status the model can hold with finite numbers (a NaN is not equal to itself)."""
    return st.builds(
        GatewayStatus,
        robot=_names,
        state=_enum(GatewayState),
        reason=_names,
        command=st.builds(CommandReport, _twists, _twists, st.booleans(), _numbers, _numbers),
        motors=st.lists(_motors, max_size=3).map(tuple),
        tracking=_tracking,
        odometry=_odometry,
        counters=st.builds(Counters, _events, _by_driver, _by_driver),
        socket=st.builds(SocketReport, _names,
                         st.builds(ServerCounters, *[_counts_st] * 11)),
        timing=_timing,
        last_error=st.none() | st.builds(LastError, _enum(ErrorCode), _names),
        realtime=st.lists(_names, max_size=2).map(tuple),
        bus=st.builds(BusReport, _names, _names, st.integers(0, 10**7), _health, _counts_st,
                      _numbers, _frames),
        config=st.none() | st.builds(ConfigReport, _names, _names),
    )
