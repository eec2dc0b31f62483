"""CiA 402: a feedback TPDO whose statusword matches no drive state is malformed, on a running
robot (the tricycle: a CiA 402 drive motor and steering actuator, with their simulators):
counted as a rejection, its value never reaches the wheel's feedback or the odometry."""

from __future__ import annotations

from drivers.cia402.codec import make_tpdo
from drivers.cia402.enums import tpdo_cob_id
from gateway.bus.can_bus import send_frames
from gateway.core.types import GatewayState
from tests.drivers.cia402_bench import rolling_tricycle


def test_a_tpdo_whose_statusword_matches_no_state_is_not_taken() -> None:
    with rolling_tricycle("cia402-bad-statusword", 0.2) as (rig, drv, i):
        node = drv.motors[i].node_id
        layout = drv.codec.nodes[node]
        before = drv.feedback(i)
        assert before is not None
        # Statusword 0x0002 (bit 1 without bit 0: no state of the CiA 402 table), on the
        # velocity TPDO with 2e9 and on the position TPDO with a jump of 2**30 counts.
        send_frames(rig.pilot, [
            make_tpdo(tpdo_cob_id(layout.tpdo_velocity, node), 0x0002, 2_000_000_000),
            make_tpdo(tpdo_cob_id(layout.tpdo_position, node), 0x0002, 1 << 30)])
        rig.gw.cycle(rig.t)  # exactly these frames (the simulators have not stepped since)
        assert sum(drv.rejected.values()) == 2
        assert "statusword 0x0002 matches no CiA 402 drive state" in str(drv.last_rejection)
        after = drv.feedback(i)
        assert after is not None
        assert after.velocity_rad_s == before.velocity_rad_s
        assert abs(after.position_rad - before.position_rad) < 0.1
        rig.t += rig.period
        rig.advance(0.3)
        assert rig.gw.state is GatewayState.RUNNING
        assert rig.gw.odometry.state.distance_m < 0.5
