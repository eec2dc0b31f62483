"""A motor that sends some of its liveness streams but not all is OFFLINE, and its fault says
what it sends, what it does not, and how to switch a stream on that never came
(:meth:`gateway.drive.liveness.Liveness.silence`); on the simulated controllers."""

from __future__ import annotations

from drivers.odrive.sim import OdriveSimulator
from drivers.vesc.settings import STATUS_1, STATUS_WHERE
from drivers.vesc.sim import VescSimulator
from gateway.core.types import GatewayState, Twist
from gateway.drive.liveness import Liveness
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, virtual_config

ODRIVE_HINT = ("set axis<n>.config.can.encoder_msg_rate_ms (0.6) or encoder_rate_ms (0.5), "
               "10 ms from the factory")


def test_an_odrive_without_encoder_estimates_says_so_and_how_to_switch_them_on(
        channel: str) -> None:
    with Rig(virtual_config(None, channel, rate_hz=100.0)) as rig:
        sim = rig.sims[0]
        assert isinstance(sim, OdriveSimulator)
        sim.encoder_period_s = 0.0  # axis.config.can.encoder_msg_rate_ms = 0
        rig.gw.supervisor.enable(rig.t)
        rig.advance(6.0)
        assert rig.gw.state is GatewayState.FAULT
        assert rig.gw.supervisor.reason == (
            f"motor '{sim.motor.wheel}' (node {sim.motor.node_id}) did not enable within 5 s, "
            f"and it sends its heartbeat but no encoder estimates (none yet): {ODRIVE_HINT}")


def test_an_odrive_whose_estimates_stop_names_them_not_its_heartbeat(channel: str) -> None:
    with Rig(virtual_config(None, channel, rate_hz=100.0)) as rig:
        rig.enable()
        rig.advance(0.5, lambda r: r.send_can_twist(Twist(0.2, 0.0, 0.0)))
        sim = rig.sims[0]
        assert isinstance(sim, OdriveSimulator)
        sim.encoder_period_s = 0.0
        rig.advance(0.5, lambda r: r.send_can_twist(Twist(0.2, 0.0, 0.0)))
        assert rig.gw.state is GatewayState.FAULT
        reason = rig.gw.supervisor.reason
        prefix = (f"motor '{sim.motor.wheel}' (node {sim.motor.node_id}) sends its heartbeat "
                  f"but no encoder estimates (none for 0.2")
        assert reason.startswith(prefix), reason
        assert reason.endswith(" s)")  # (no hint: the stream came before)


def test_a_vesc_without_status_5_says_where_to_tick_it(channel: str) -> None:
    """The motor setup wizard ticks Status 1 to 4 only: the tachometer never comes."""
    with Rig(virtual_config(CONFIG_DIR / "skid_steer.yaml", channel, rate_hz=100.0)) as rig:
        sim = rig.sims[0]
        assert isinstance(sim, VescSimulator)
        sim.status_msgs = STATUS_1
        rig.gw.supervisor.enable(rig.t)
        rig.advance(6.0)
        assert rig.gw.state is GatewayState.FAULT
        assert (f"motor '{sim.motor.wheel}' (node {sim.motor.node_id}) did not enable within "
                f"5 s, and it sends its STATUS but no STATUS_5 (none yet): tick Status 5 in "
                f"{STATUS_WHERE} (the motor setup wizard ticks Status 1 to 4 only)"
                ) in rig.gw.supervisor.reason


def test_silence_says_nothing_when_every_stream_or_none_is_silent() -> None:
    live = Liveness(2, ("a", "b"), [0.25, 0.25])
    assert live.silence(0, 1.0, {"a": "hint"}) == ""  # nothing heard: "has not answered"
    live.heard(0, 0, 1.0)
    live.heard(0, 1, 1.0)
    assert live.silence(0, 1.1, {}) == ""  # all heard
    assert live.silence(0, 2.0, {}) == ""  # all too old: "stopped answering"
    live.heard(1, 1, 1.9)
    assert live.silence(1, 2.0, {"a": "switch a on"}) == (
        "sends its b but no a (none yet): switch a on")
    # A node silent as a whole: its heartbeat (every 100 ms) was last heard 90 ms before its
    # estimates (every 10 ms); when the heartbeat's limit runs out the estimates are younger,
    # but they were not heard after the heartbeat stopped: not "sends its estimates".
    live.heard(1, 0, 1.91)
    live.heard(1, 1, 2.0)
    assert live.silence(1, 2.17, {}) == ""
    live.heard(1, 1, 2.16)  # heard 160 ms after: it still comes
    assert live.silence(1, 2.17, {}) == "sends its b but no a (none for 0.260 s)"
