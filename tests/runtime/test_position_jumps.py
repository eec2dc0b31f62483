"""A wheel position that jumps (a controller that restarted its count, a corrupt value) is not
taken for motion by the gateway's odometry (:mod:`gateway.core.odom_feed`): checked on the
simulated controllers, against the simulators' true wheel angles."""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

import pytest

from drivers.odrive.codec import OdriveCodec
from drivers.vesc.sim import VescSimulator
from gateway.bus.can_bus import send_frames
from gateway.core.types import GatewayState, Twist
from gateway.sim.device import SimFault
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, virtual_config

if TYPE_CHECKING:
    from gateway.core.kinematics.odometry import Pose

FORWARD = Twist(0.3, 0.0, 0.1)


def gap(a: Pose, b: Pose) -> float:
    return math.hypot(a.x_m - b.x_m, a.y_m - b.y_m)


def drive(rig: Rig, seconds: float, twist: Twist = FORWARD) -> None:
    rig.advance(seconds, lambda r: r.send_can_twist(twist))


def test_a_corrupt_position_is_not_integrated(channel: str, caplog: pytest.LogCaptureFixture
                                              ) -> None:
    """One ODrive encoder estimate of 1e30 turns (a finite float32) among the true ones: the
    odometry neither jumps there nor back, and the log names the wheel."""
    with Rig(virtual_config(None, channel, rate_hz=100.0)) as rig:
        rig.enable()
        drive(rig, 1.0)
        motor = rig.config.motors[0]
        assert motor is not None and motor.driver == "odrive"
        codec = OdriveCodec.from_options(motor.options)
        with caplog.at_level(logging.WARNING, logger="gateway.runtime.loop"):
            send_frames(rig.pilot, [codec.make_encoder_estimates(motor.node_id, 1e30, 0.0)])
            drive(rig, 1.0)
        odo, truth = rig.gw.odometry.state, rig.truth.state
        # At most two samples' motion of one wheel missing (10 ms at 100 Hz each).
        assert gap(odo.pose, truth.pose) < 0.01
        assert odo.distance_m == pytest.approx(truth.distance_m, abs=0.01)
        assert abs(odo.pose.theta_rad - truth.pose.theta_rad) < 0.02
        assert rig.gw.counts.position_jumps == 2  # there, and back
        assert rig.gw.state is GatewayState.RUNNING
        lines = [r.getMessage() for r in caplog.records if "position stepped" in r.getMessage()]
        assert len(lines) == 1  # one line per 5 s, with the count
        step = 1e30 * 2 * math.pi / motor.gear_ratio  # turns of the motor, rad at the wheel
        assert lines[0].startswith(f"odometry: wheel {motor.wheel!r}: its position stepped "
                                   f"{step:+.6g} rad in 0.010 s, more than it can turn")
        assert "restart of its controller's position count or a corrupt value" in lines[0]


def test_a_power_cycled_vesc_does_not_throw_the_odometry_back(channel: str) -> None:
    """A VESC that loses power while driving: silent for 0.4 s (the gateway faults, stops the
    other wheels and recovers), then back with its tachometer at 0.  The odometry goes on
    from where it was instead of taking the count's return to 0 as the wheel turning back."""
    cfg = virtual_config(CONFIG_DIR / "skid_steer.yaml", channel, rate_hz=100.0)
    with Rig(cfg) as rig:
        vesc = rig.sims[0]
        assert isinstance(vesc, VescSimulator)
        # As a VESC that had been counting before wheelgate started (its tachometer is a
        # RAM counter from its own power-up): a count that its return to 0 makes plain.
        vesc._initial_tacho = 2_000_000  # (private: the device's state before the test)
        rig.enable()
        drive(rig, 1.5)
        travelled = rig.truth.state.distance_m
        assert travelled > 0.3
        vesc.inject(SimFault.SILENT)
        vesc.power_cycle()
        rig.advance(0.4)
        vesc.clear(SimFault.SILENT)
        rig.advance(1.0)
        if rig.gw.state is not GatewayState.RUNNING:
            rig.enable()
        drive(rig, 1.5)
        odo, truth = rig.gw.odometry.state, rig.truth.state
        assert truth.distance_m > 2 * travelled
        # What the VESC's wheel turned while it was silent is lost (it coasted down).
        assert gap(odo.pose, truth.pose) < 0.05
        assert odo.distance_m == pytest.approx(truth.distance_m, abs=0.05)
        assert rig.gw.counts.position_jumps == 1
