"""Shared helpers of the tests of wheelgate's own CAN messages (test_wgproto_*): the DBC loaded
with cantools, the codec, and decoding a frame both ways."""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import cantools
from hypothesis import settings

from gateway.core.kinematics.odometry import Pose
from gateway.wire.can import (
    OdomVelocity,
    StatusFlags,
    StatusReport,
    TwistCommand,
    TwistFlags,
    WgCodec,
    WgMessage,
)
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from collections.abc import Mapping

    from cantools.database import Database, Message

DBC = str(CONFIG_DIR / "wheelgate.dbc")
CODEC = WgCodec()
SETTINGS = settings(max_examples=150, deadline=None)
MM = 0.001
#: Message name -> CanIds key.
MESSAGES = {
    "WG_Twist_Cmd": "twist",
    "WG_Odom_Pose": "odom_pose",
    "WG_Odom_Velocity": "odom_velocity",
    "WG_Status": "status",
    "WG_Error": "error",
}


@functools.cache
def database() -> Database:
    db = cantools.database.load_file(DBC, strict=True)
    assert isinstance(db, cantools.database.can.Database)
    return db


def message(name: str) -> Message:
    msg: Message = database().get_message_by_name(name)
    return msg


def cantools_decode(name: str, data: bytes) -> Mapping[str, object]:
    """cantools' reading of a payload, numbers rather than value-table names."""
    values = message(name).decode(data, decode_choices=False)
    assert isinstance(values, dict)
    return values


def signals(decoded: WgMessage) -> dict[str, float]:
    """The DBC signal values of a decoded message (what cantools should read)."""
    if isinstance(decoded, TwistCommand):
        tw, f = decoded.twist, decoded.flags
        return {
            "Vx": tw.vx_m_s, "Vy": tw.vy_m_s, "Wz": tw.wz_rad_s, "Counter": decoded.counter,
            "Estop_Request": int(TwistFlags.ESTOP in f),
            "Enable_Request": int(TwistFlags.ENABLE in f),
            "Stop_Request": int(TwistFlags.STOP in f),
        }  # fmt: skip
    if isinstance(decoded, Pose):
        return {"X": decoded.x_m, "Y": decoded.y_m, "Theta": decoded.theta_rad}
    if isinstance(decoded, OdomVelocity):
        tw = decoded.twist
        return {"Vx": tw.vx_m_s, "Vy": tw.vy_m_s, "Wz": tw.wz_rad_s, "Slip": decoded.slip_m_s}
    if isinstance(decoded, StatusReport):
        s = decoded.flags
        return {
            "State": int(decoded.state), "Faulted_Motors": decoded.faulted_motors,
            "Counter": decoded.counter,
            "Cmd_Timeout_Active": int(StatusFlags.CMD_TIMEOUT_ACTIVE in s),
            "Speed_Limited": int(StatusFlags.SPEED_LIMITED in s),
            "Projected": int(StatusFlags.PROJECTED in s),
            "Bus_Errors_Recent": int(StatusFlags.BUS_ERRORS_RECENT in s),
            "Missed_Cycles": decoded.missed_cycles, "Infeasible_Count": decoded.infeasible_count,
        }  # fmt: skip
    return {
        "Code": int(decoded.code), "Wheel": decoded.wheel, "Constraint": int(decoded.constraint),
        "Twist_Counter": decoded.twist_counter, "Residual": decoded.residual_m_s,
        "Count": decoded.count,
    }  # fmt: skip
