"""An enable that fails says why: a CiA 402 drive whose answers come later than the enable
sequence waits for (a slow gateway-to-bus adapter, a drive busy with something else, a host
stalled for longer than the deadline) leaves the gateway in FAULT with the step that got no
answer in its reason, at once rather than when its enable timeout ends; and
``response_timeout_s`` on the motor block lengthens that wait for such a drive."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest
import yaml

from drivers.cia402.enums import State
from gateway.config import load_config
from gateway.core.types import GatewayState, Twist
from gateway.sim.device import SimFault
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, virtual_config

if TYPE_CHECKING:
    from pathlib import Path

    from drivers.cia402.sim import Cia402Simulator

pytestmark = pytest.mark.timeout(60)

#: How late the drive's every frame is (s): longer than the default wait of 0.5 s.
LATENCY_S = 0.7


def slow_tricycle(tmp_path: Path, channel: str, enable_timeout_s: float, **drive: object) -> Rig:
    """The tricycle (CiA 402 drive and steering) on a virtual bus, ``drive`` added to its drive
    motor's block, and that drive's answers ``LATENCY_S`` late."""
    raw = yaml.safe_load((CONFIG_DIR / "tricycle.yaml").read_text())
    raw["motors"]["front"].update(drive, liveness_s=2.0)
    raw["gateway"] = {"rate_hz": 100.0, "enable_timeout_s": enable_timeout_s}
    raw["bus"] = {"interface": "virtual", "channel": channel}
    path = tmp_path / "tricycle.yaml"
    path.write_text(yaml.safe_dump(raw))
    rig = Rig(load_config(path))
    sim = rig.sims[0]
    assert not sim.motor.steering and sim.motor.node_id == 5
    sim.latency_s = LATENCY_S
    sim.inject(SimFault.LATE)
    return rig


def drive_state(drive: Cia402Simulator) -> State:
    """The simulated drive's state, read through a call (as :func:`state_of`)."""
    return drive.state


def state_of(rig: Rig) -> GatewayState:
    """The state, read through a call so mypy does not narrow it across steps."""
    return rig.gw.state


def test_an_enable_that_fails_names_the_step_that_got_no_answer_at_once(
    tmp_path: Path, channel: str
) -> None:
    """The sequence fails on its first late answer: the gateway faults then, naming the step,
    not when its enable timeout ends; an enable after the drive is fixed starts afresh (the
    failure of the last sequence is not taken for this one's)."""
    with slow_tricycle(tmp_path, channel, 30.0) as rig:
        rig.gw.supervisor.enable(rig.t)
        start = rig.t
        while state_of(rig) is GatewayState.ENABLING and rig.t - start < 30.0:
            rig.advance(0.05)
        assert rig.gw.state is GatewayState.FAULT
        assert rig.t - start < 3.0
        assert rig.gw.supervisor.reason == (
            "motor 'front' (node 5) failed its enable sequence, and it reports a fault: "
            'node 5 ("front"): no SDO response within 0.5 s to the write of 0 to 0x1603:00 '
            "(RPDO4 mapping count, clear)")
        drive: Cia402Simulator = rig.sims[0]  # type: ignore[assignment]
        assert drive.state is not State.OPERATION_ENABLED
        drive.clear(SimFault.LATE)
        faults = rig.gw.supervisor.counts.faults
        rig.gw.supervisor.enable(rig.t)
        rig.advance(3.0)
        assert state_of(rig) is GatewayState.RUNNING, rig.gw.supervisor.reason
        assert rig.gw.supervisor.counts.faults == faults
        assert drive_state(drive) is State.OPERATION_ENABLED


def test_response_timeout_s_waits_longer_for_a_slow_drive(tmp_path: Path, channel: str) -> None:
    # Some 30 SDO exchanges of 2 x 0.7 s each: the enable takes about 45 s of simulated time.
    with slow_tricycle(tmp_path, channel, 90.0, response_timeout_s=1.5) as rig:
        rig.enable(timeout_s=90.0)
        assert rig.gw.state is GatewayState.RUNNING, rig.gw.supervisor.reason
        drive: Cia402Simulator = rig.sims[0]  # type: ignore[assignment]
        assert drive.state is State.OPERATION_ENABLED


def test_a_drive_that_boots_after_the_gateway_is_waited_for(tmp_path: Path, channel: str) -> None:
    """A drive powered with the gateway's computer may boot after the gateway sends its first
    request: a node that has said nothing yet is asked again until it answers, within the
    gateway's enable timeout (this raced in the socketcan tier, where ``wheelgate run`` and
    ``wheelgate sim`` start together)."""
    with slow_tricycle(tmp_path, channel, 10.0) as rig:
        drive = rig.sims[0]
        drive.clear(SimFault.LATE)
        drive.inject(SimFault.SILENT)  # not booted yet
        rig.gw.supervisor.enable(rig.t)
        rig.advance(2.0)
        assert state_of(rig) is GatewayState.ENABLING, rig.gw.supervisor.reason
        drive.clear(SimFault.SILENT)
        rig.advance(3.0)
        assert state_of(rig) is GatewayState.RUNNING, rig.gw.supervisor.reason
        assert rig.gw.supervisor.counts.faults == 0


def test_a_dbc_controller_powered_after_the_enable_gets_its_enable_message(
    channel: str,
) -> None:
    """A DBC controller armed by a separate enable message (the example's WD_Enable), which it
    never answers: one powered after the gateway enabled it missed the message.  Once it is
    heard, the enable message goes out again, so its wheel turns when commanded (this raced in
    the socketcan tier: the gateway RUNNING, the simulated wheels still)."""
    cfg = virtual_config(CONFIG_DIR / "example_dbc.yaml", channel, rate_hz=100.0)
    with Rig(cfg) as rig:
        for sim in rig.sims:
            sim.inject(SimFault.SILENT)  # not powered yet: hears nothing, says nothing
        rig.gw.supervisor.enable(rig.t)
        rig.advance(0.5)
        for sim in rig.sims:
            sim.clear(SimFault.SILENT)
        rig.advance(0.5)
        assert state_of(rig) is GatewayState.RUNNING, rig.gw.supervisor.reason
        rig.advance(1.0, lambda r: r.send_can_twist(Twist(0.3, 0.0, 0.0)))
        assert all(sim.model.armed for sim in rig.sims)
        assert all(abs(sim.model.velocity_rad_s) > 10.0 for sim in rig.sims)  # motor side
