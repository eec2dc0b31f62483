"""CiA 402: a feedback TPDO whose statusword matches no drive state is malformed, on a running
robot (the tricycle: a CiA 402 drive motor and steering actuator, with their simulators):
counted as a rejection, its value never reaches the wheel's feedback or the odometry."""

from __future__ import annotations

from drivers.cia402 import Cia402Driver
from drivers.cia402.codec import make_tpdo
from drivers.cia402.enums import tpdo_cob_id
from gateway.bus.can_bus import send_frames
from gateway.core.types import GatewayState, Twist
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, virtual_config


def test_a_tpdo_whose_statusword_matches_no_state_is_not_taken() -> None:
    cfg = virtual_config(CONFIG_DIR / "tricycle.yaml", "cia402-bad-statusword")
    with Rig(cfg) as rig:
        rig.enable()
        for _ in range(6):
            rig.send_can_twist(Twist(0.2))
            rig.advance(0.05)
        drv = next(d for d, _ in rig.gw.drives.groups if isinstance(d, Cia402Driver))
        i = next(k for k, m in enumerate(drv.motors) if not m.steering)
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
