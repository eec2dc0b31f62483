"""CiA 402: an armed drive lives by its position TPDO.  A drive whose position TPDO stops while
its velocity TPDO and heartbeat go on (a lost PDO mapping, a drive that sends it no more) would
leave the odometry frozen under a turning wheel; the tracking check sees only the velocity.  On
the tricycle (a CiA 402 drive motor and steering actuator, with their simulators) the drive goes
OFFLINE within its ``liveness_s``, the gateway stops, and the simulated wheel stops."""

from __future__ import annotations

from drivers.cia402.enums import PDO_COB_INVALID
from drivers.cia402.sim import Cia402Simulator
from gateway.core.types import DriveState, GatewayState, Twist
from tests.drivers.cia402_bench import rolling_tricycle

#: TPDO3's communication parameter: statusword + position in the driver's default layout.
POSITION_TPDO_COMM = 0x1802


def test_a_drive_whose_position_tpdo_stops_goes_offline_and_the_wheel_stops() -> None:
    with rolling_tricycle("cia402-position-tpdo", 0.3) as (rig, drv, i):
        (sim,) = rig.drive_sims
        assert isinstance(sim, Cia402Simulator)
        assert abs(sim.wheel_velocity_rad_s) > 1.0
        # The drive's TPDO3 COB-ID (0x1802:01) made invalid (bit 31, CiA 301): it
        # sends its position no more; the velocity TPDO, heartbeat and the rest go on.
        cob = sim.od.get(POSITION_TPDO_COMM, 1)
        sim.od.set(POSITION_TPDO_COMM, cob | PDO_COB_INVALID, 1)
        liveness = drv.opts[i].liveness_s
        t0 = rig.t
        while rig.gw.state is GatewayState.RUNNING and rig.t - t0 < liveness + 1.0:
            rig.send_can_twist(Twist(0.3))
            rig.advance(rig.period)
        assert rig.gw.state is not GatewayState.RUNNING
        assert rig.t - t0 <= liveness + 0.1
        assert drv.state(i, rig.t) is DriveState.OFFLINE
        # Named as what stopped: its other frames come (not "stopped answering").
        m = drv.motors[i]
        assert rig.gw.supervisor.reason.startswith(
            f"motor '{m.wheel}' (node {m.node_id}) sends its other frames but no position TPDO "
            f"(statusword and position actual value 0x6064; none for 0.2"), rig.gw.supervisor.reason
        rig.advance(1.5)
        assert abs(sim.wheel_velocity_rad_s) < 0.05
