"""Controllers that send at their own phases: the gateway's odometry integrates every wheel at
one time (:class:`gateway.core.odom_feed.OdomFeed`'s whole rounds), not one wheel at a time.

Real controllers are not synchronised: an ODrive sends its encoder estimates on its own 10 ms
timer from its own power-up, a VESC its STATUS frames at its own rate.  The simulators start
their timers together (the first cycle), so these tests shift them apart, 2.5 ms from one to
the next, and judge the gateway's odometry against the simulators' true wheel angles.  Before
whole rounds a 1 kHz loop took a sample at every wheel's new position: the mecanum robot's
distance came out 41 % long and its odometry's twist was one wheel's alone (driving straight
at 0.5 m/s: 0.42 m/s forward, 0.42 m/s sideways, 1.1 rad/s of turn)."""

from __future__ import annotations

import math

import pytest

from drivers.odrive.sim import OdriveSimulator
from drivers.vesc.sim import VescSimulator
from gateway.core.types import GatewayState, Twist
from gateway.sim.device import SimFault
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, virtual_config

#: From one controller's feedback timer to the next one's (s).
PHASE_S = 0.0025


def stagger(rig: Rig) -> None:
    """Every controller's feedback timer shifted ``PHASE_S`` from the one before."""
    for k, sim in enumerate(rig.sims):
        if isinstance(sim, OdriveSimulator):
            sim._next_encoder_s = k * PHASE_S + 1e-4  # (private: the device's own phase)
        elif isinstance(sim, VescSimulator):
            sim._next_status_s = k * PHASE_S + 1e-4
        else:
            raise AssertionError(f"no phase to shift on {type(sim).__name__}")


def check(rig: Rig, twist_abs: float = 0.01) -> None:
    """The odometry against the simulators' truth; its twist within ``twist_abs``."""
    odo, truth = rig.gw.odometry.state, rig.truth.state
    assert truth.distance_m > 1.0
    assert odo.distance_m == pytest.approx(truth.distance_m, rel=0.01)
    # The last sample is up to a feedback period behind the truth's end.
    assert math.hypot(odo.pose.x_m - truth.pose.x_m, odo.pose.y_m - truth.pose.y_m) < 0.01
    assert abs(odo.pose.theta_rad - truth.pose.theta_rad) < 0.005
    # At a steady speed the odometry's twist is the robot's, not one wheel's.
    got, true = odo.twist, truth.twist
    assert true.vx_m_s > 0.25
    assert (got.vx_m_s, got.vy_m_s, got.wz_rad_s) == pytest.approx(
        (true.vx_m_s, true.vy_m_s, true.wz_rad_s), abs=twist_abs)


@pytest.mark.parametrize("twist", [Twist(0.5, 0.0, 0.0), Twist(0.3, 0.2, 0.5)])
def test_mecanum_odrives_at_their_own_phases(channel: str, twist: Twist) -> None:
    with Rig(virtual_config(None, channel, rate_hz=1000.0)) as rig:
        stagger(rig)
        rig.enable()
        rig.advance(4.0, lambda r: r.send_can_twist(twist))
        assert rig.gw.state is GatewayState.RUNNING
        check(rig)


def test_skid_steer_vescs_at_their_own_phases(channel: str) -> None:
    twist = Twist(0.5, 0.0, 0.4)
    with Rig(virtual_config(CONFIG_DIR / "skid_steer.yaml", channel, rate_hz=1000.0)) as rig:
        stagger(rig)
        rig.enable()
        rig.advance(4.0, lambda r: r.send_can_twist(twist))
        assert rig.gw.state is GatewayState.RUNNING
        # A VESC's position is its tachometer, whole steps of a sixth of an electrical turn:
        # over one 20 ms STATUS period the twist is off by a step (0.016 rad/s here, and as
        # much without the phases; 1.1 m/s and 4.1 rad/s off before whole rounds).
        check(rig, twist_abs=0.03)


def test_a_silent_wheel_stops_the_odometry_for_its_liveness_only(channel: str) -> None:
    """One ODrive falls silent while the robot drives: the odometry waits for it no longer
    than its ``liveness_s`` (when it is OFFLINE anyway), then goes on with the others."""
    twist = Twist(0.5, 0.0, 0.0)
    with Rig(virtual_config(None, channel, rate_hz=1000.0)) as rig:
        stagger(rig)
        rig.enable()
        rig.advance(1.0, lambda r: r.send_can_twist(twist))
        rig.sims[0].inject(SimFault.SILENT)
        silent_from = rig.t
        rig.advance(1.0, lambda r: r.send_can_twist(twist))
        feed = rig.gw.odom_feed
        assert rig.gw.state is not GatewayState.RUNNING  # the silent motor is a fault
        liveness = rig.gw.drives.liveness_s
        assert feed.sampled_s > silent_from + liveness  # sampled again without the wheel
        assert rig.t - feed.sampled_s < 0.05  # and goes on sampling
