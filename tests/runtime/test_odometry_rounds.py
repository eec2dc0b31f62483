"""Controllers that send at their own phases: the gateway's odometry integrates every wheel at
one time (:class:`gateway.core.odom_feed.OdomFeed`'s whole rounds), not one wheel at a time.

Real controllers are not synchronised: an ODrive sends its encoder estimates on its own 10 ms
timer from its own power-up, a VESC its STATUS frames at its own rate.  So do the simulators of
a robot (:func:`gateway.sim.registry.simulators_for` gives each a phase of its own); these tests
judge the gateway's odometry against the simulators' true wheel angles.  Before whole rounds a
1 kHz loop took a sample at every wheel's new position: the mecanum robot's distance came out
41 % long and its odometry's twist was one wheel's alone (driving straight at 0.5 m/s: 0.42 m/s
forward, 0.42 m/s sideways, 1.1 rad/s of turn).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import pytest

from drivers.odrive.enums import CmdId
from drivers.odrive.sim import OdriveSimulator
from drivers.vesc.sim import VescSimulator
from gateway.config import load_config
from gateway.core.types import GatewayState, Twist
from gateway.sim.device import SimFault, spread_phase
from gateway.sim.registry import simulators_for
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, virtual_config

if TYPE_CHECKING:
    from pathlib import Path


def spread(rig: Rig) -> None:
    """The simulators send at phases of their own (as ``simulators_for`` builds them): checked,
    so that these tests cannot pass on controllers in step."""
    phases = [sim.phase for sim in rig.sims]
    assert len(set(phases)) == len(phases) > 1, phases
    assert all(isinstance(sim, (OdriveSimulator, VescSimulator)) for sim in rig.sims)


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
        spread(rig)
        rig.enable()
        rig.advance(4.0, lambda r: r.send_can_twist(twist))
        assert rig.gw.state is GatewayState.RUNNING
        check(rig)


def test_skid_steer_vescs_at_their_own_phases(channel: str) -> None:
    twist = Twist(0.5, 0.0, 0.4)
    with Rig(virtual_config(CONFIG_DIR / "skid_steer.yaml", channel, rate_hz=1000.0)) as rig:
        spread(rig)
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
        spread(rig)
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


@pytest.mark.parametrize(("config", "period_s"), [
    (None, 0.01),  # ODrive estimates
    (CONFIG_DIR / "skid_steer.yaml", 0.02),  # VESC STATUS
    (CONFIG_DIR / "mecanum.yaml", 0.001),  # DJI feedback
    (CONFIG_DIR / "example_dbc.yaml", None),  # DBC feedback message
])
def test_the_simulators_of_a_robot_send_at_phases_of_their_own(
        config: Path | None, period_s: float | None) -> None:
    """Each simulator's first cyclic frame goes out its phase of a period after its first
    tick: a robot's simulators started together are not in step."""
    cfg = load_config(config)
    sims = simulators_for(m for m in cfg.motors if m is not None)
    step = 1e-5
    first: list[float | None] = [None] * len(sims)
    t = 0.0
    while None in first and t < 1.0:
        for k, sim in enumerate(sims):
            sent = sim.tick(t)
            if isinstance(sim, OdriveSimulator):  # (not its heartbeat, every 100 ms)
                sent = [f for f in sent if f.arbitration_id & 0x1F != CmdId.HEARTBEAT]
            if first[k] is None and sent:
                first[k] = t
        t += step
    for k, sim in enumerate(sims):
        period = period_s if period_s is not None else sim.period_s  # type: ignore[attr-defined]
        assert sim.phase == spread_phase(k)
        assert first[k] == pytest.approx(sim.phase * period, abs=2 * step), k
    assert len(set(first)) == len(first)
