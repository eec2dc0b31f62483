"""DBC: a motor whose velocity and position come in two messages (``position_message``) is
alive only while both come: one message that stopped leaves no value standing as fresh
feedback (a frozen position would freeze the odometry, a frozen velocity hide a blocked wheel
from the tracking check), and the feedback's age in a report is the older message's."""

from __future__ import annotations

import cantools
import pytest

from drivers.dbc import DbcDriver
from gateway.core.types import DriveState, Frame
from tests.drivers.dbc_helpers import ANGLE, EXAMPLE_DBC, motor

DB = cantools.database.load_file(EXAMPLE_DBC)
assert isinstance(DB, cantools.database.can.Database)
FEEDBACK, ANGLE_MSG = DB.get_message_by_name("WD_Feedback"), DB.get_message_by_name("WD_Angle")
NODE = 3


def velocity_frame(t: float) -> Frame:
    return Frame(FEEDBACK.frame_id + NODE, FEEDBACK.encode(
        {"Actual_Velocity": 1200.0, "Position_Count": 0, "Fault_Code": 0, "Drive_Temp": 20}),
        timestamp_s=t)


def angle_frame(t: float, deg: float) -> Frame:
    return Frame(ANGLE_MSG.frame_id + NODE, ANGLE_MSG.encode(
        {"Rotor_Angle": deg, "Bus_Voltage": 24}), timestamp_s=t)


@pytest.mark.parametrize("stops", ["position", "velocity"])
def test_a_motor_whose_two_feedback_messages_one_stops_goes_offline(stops: str) -> None:
    drv = DbcDriver([motor(NODE, extra=ANGLE)])
    drv.enable(0.0)
    t, deg = 0.0, 0.0
    for k in range(100):  # 1 s of both messages at 100 Hz
        t, deg = k * 0.01, (deg + 72.0) % 360.0
        drv.on_frame(angle_frame(t, deg))
        drv.on_frame(velocity_frame(t))
    assert drv.state(0, t) is DriveState.ENABLED
    last_both = t
    for k in range(100, 400):  # 3 s of one of them only
        t = k * 0.01
        drv.on_frame(velocity_frame(t) if stops == "position" else angle_frame(t, deg))
    assert drv.state(0, t) is DriveState.OFFLINE
    assert drv.live.silent(0, t) == [stops]
    # The feedback is stamped with its position's time (what the odometry integrates it at);
    # its age in a report is the older message's either way.
    fb = drv.feedback(0)
    assert fb is not None
    assert fb.timestamp_s == pytest.approx(last_both if stops == "position" else t)
    age = drv.status(t)[0].feedback_age_s
    assert age is not None and age == pytest.approx(t - last_both)
    assert not drv.rejected
