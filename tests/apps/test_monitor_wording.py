"""The monitor's screen says each thing once and plainly: the error frames with their classes
in parentheses, the time since watching began (not a monotonic clock), and a visible mark
where a name or a line is cut to the terminal's width."""

from __future__ import annotations

from gateway.apps.layout import CUT
from gateway.apps.monitor import BusLoad, IdView, MonitorSnapshot, MotorView, render
from gateway.drive.labels import FrameLabel

LONG = "front_axle steering linkage actuator"


def snapshot(source: str = "daemon /run/wheelgate/wheelgate.sock") -> MonitorSnapshot:
    motor = MotorView(LONG, "odrive", 5, "enabled", (), "", None, None, 0.1, 0.01, ("a", "b"))
    ids = (IdView(0x0A9, False, False, "rx", 10, 5.0,
                  FrameLabel(f"ODrive node 5 Get_Encoder_Estimates ({LONG}, with a label "
                             "that runs past the edge of any terminal)")),)
    return MonitorSnapshot(source, 50882.39, 12.345, 2.0, 10, BusLoad(1_000_000, 5.0, 0.5, 0.6),
                           (motor,), ids, (("bus error frames", 3),
                                           ("bus error frames: no ack", 2),
                                           ("bus error frames: bus off", 1),
                                           ("receive errors", 0)))


def test_error_frames_are_said_once_with_their_classes() -> None:
    text = render(snapshot(), 200)
    assert "errors: bus error frames 3 (no ack 2, bus off 1), receive errors 0" in text
    assert text.count("error frames") == 1


def test_the_header_shows_the_time_since_watching_began() -> None:
    text = render(snapshot(), 200)
    assert "50882" not in text  # the source's monotonic clock means nothing to a reader
    assert "watching for 12.3 s" in text.splitlines()[0]
    log = render(snapshot("log robot.log"), 200)
    assert "12.345 s into the log" in log.splitlines()[0]


def test_cuts_are_marked_and_fit_80_columns() -> None:
    for height in (None, 24):
        lines = render(snapshot(), 79, height).splitlines()
        assert all(len(line) <= 79 for line in lines)
        motor = next(line for line in lines if line.startswith(LONG[:12]))
        assert motor.startswith(LONG[:19] + CUT + " ")  # the name column: 20 with its space
        label = next(line for line in lines if line.startswith("0x0A9"))
        assert len(label) == 79 and label.endswith(CUT)
