"""The CiA 402 driver against its simulator on a python-can virtual bus, and the SDO client
against canopen's server (and canopen's client against the simulator)."""

from __future__ import annotations

import contextlib
import dataclasses
from typing import TYPE_CHECKING

import can
import canopen
import pytest
from canopen.sdo.exceptions import SdoAbortedError

from drivers.cia402 import Cia402Driver, Cia402Simulator
from drivers.cia402.codec import (
    make_nmt,
    make_sync,
    make_tpdo,
)
from drivers.cia402.enums import (
    DataType,
    NmtCommand,
    NmtState,
    ServerCommand,
    State,
)
from drivers.cia402.sdo import (
    make_sdo_download,
    make_sdo_upload,
    parse_sdo_response,
)
from drivers.cia402.sequence import Phase
from gateway.bus.can_bus import drain, send_frames
from gateway.core.types import DriveFault, DriveState, Frame, MotorConfig
from gateway.sim.bus import SimulatedControllers
from gateway.sim.device import SimFault
from tests.drivers.test_drivers_cia402 import DT, TWO_PI, hexb

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator, Sequence


@dataclasses.dataclass
class Bench:
    drv: Cia402Driver
    sims: Sequence[Cia402Simulator]
    gw: can.BusABC
    ctl: SimulatedControllers
    t: float = 0.0
    seen: list[Frame] = dataclasses.field(default_factory=list)
    sent: list[Frame] = dataclasses.field(default_factory=list)

    def send(self, frames: Sequence[Frame]) -> None:
        send_frames(self.gw, frames)
        self.sent += frames

    def run(self, seconds: float, speeds: Sequence[float] | None = None,
            until: Callable[[], bool] | None = None) -> bool:
        """Step simulated time; ``speeds`` None means the loop does not call command()."""
        for _ in range(round(seconds / DT)):
            self.t += DT
            self.ctl.step(self.t)
            for raw in drain(self.gw):
                f = raw.stamped(self.t)
                self.seen.append(f)
                self.drv.on_frame(f)
            out = self.drv.poll(self.t)
            if speeds is not None:
                out += self.drv.command(speeds, self.t)
            self.send(out)
            if until is not None and until():
                return True
        return until is None

    def state(self, i: int = 0) -> DriveState:
        return self.drv.state(i, self.t)

    def enable(self, speeds: Sequence[float] | None = None, seconds: float = 0.5) -> bool:
        self.send(self.drv.enable(self.t))
        return self.run(seconds, speeds, until=lambda: all(
            self.state(i) is DriveState.ENABLED for i in range(len(self.sims))))


@contextlib.contextmanager
def benches(channel: str) -> Iterator[Callable[..., Bench]]:
    """A maker of benches on ``channel``, shutting every bench down at the end."""
    made: list[Bench] = []

    def make(motors: Sequence[MotorConfig], sim_class: type[Cia402Simulator] = Cia402Simulator,
             **sim_kwargs: object) -> Bench:
        drv = Cia402Driver(motors)
        sims = [sim_class(m, **sim_kwargs) for m in motors]  # type: ignore[arg-type]
        ctl = SimulatedControllers(sims, channel)
        try:
            gw = can.Bus(interface="virtual", channel=channel)
        except Exception:
            ctl.shutdown()
            raise
        made.append(Bench(drv, sims, gw, ctl))
        return made[-1]

    try:
        yield make
    finally:
        for b in made:
            b.gw.shutdown()
            b.ctl.shutdown()


@pytest.fixture
def bench(channel: str) -> Iterator[Callable[..., Bench]]:
    with benches(channel) as make:
        yield make


LEFT = MotorConfig("left", "cia402", 3, gear_ratio=10.0)
RIGHT = MotorConfig("right", "cia402", 5, gear_ratio=10.0, invert=True)
COUNT_RAD = TWO_PI / 4096 / 10.0  # one position count at the wheel


def test_enable_drive_and_read_position(bench: Callable[..., Bench]) -> None:
    b = bench([LEFT, RIGHT])
    assert b.enable([0.0, 0.0])
    for sim in b.sims:  # the gateway's layout, not the simulator's defaults
        assert sim.object_value(0x1603, 1) == 0x60400010
        assert sim.object_value(0x1603, 2) == 0x60FF0020
        assert sim.object_value(0x1A02, 2) == 0x60640020
        assert sim.object_value(0x1A03, 2) == 0x606C0020
        assert sim.object_value(0x1800, 1) & 0x80000000
        assert sim.object_value(0x6061) == 3 and sim.object_value(0x1017) == 100
        assert sim.state is State.OPERATION_ENABLED and sim.aborts == 0
    start = len(b.sent)
    b.run(1.0, [4.0, -2.5])
    cycles = 1000
    assert sum(f.arbitration_id == 0x080 for f in b.sent[start:]) == cycles  # one SYNC per bus
    for i, (sim, want) in enumerate(zip(b.sims, (4.0, -2.5), strict=True)):
        fb = b.drv.feedback(i)
        assert fb is not None
        assert fb.velocity_rad_s == pytest.approx(want, abs=TWO_PI / 60 / 10)  # 1 RPM motor
        assert sim.wheel_velocity_rad_s == pytest.approx(want, abs=0.01)
    b.run(0.3, [0.0, 0.0])
    for i, sim in enumerate(b.sims):
        fb = b.drv.feedback(i)
        assert fb is not None
        assert fb.position_rad == pytest.approx(sim.wheel_position_rad, abs=1.01 * COUNT_RAD)
    assert b.drv.feedback(0).position_rad > 3.5  # type: ignore[union-attr]
    assert b.drv.feedback(1).position_rad < -2.0  # type: ignore[union-attr]
    assert not any(f.arbitration_id in (0x183, 0x283, 0x185, 0x285) for f in b.seen)
    assert not b.drv.rejected


def test_position_wraps_int32_end_to_end(bench: Callable[..., Bench]) -> None:
    motor = MotorConfig("left", "cia402", 3, gear_ratio=1.0, options={"counts_per_rev": 4096})
    b = bench([motor], initial_position=(1 << 31) - 3000)
    assert b.enable([0.0])
    b.run(1.5, [6.0])
    b.run(0.3, [0.0])
    assert b.sims[0].position_counts < 0  # wrapped
    fb = b.drv.feedback(0)
    assert fb is not None and fb.position_rad > 8.0
    assert fb.position_rad == pytest.approx(b.sims[0].wheel_position_rad, abs=TWO_PI / 4096)


def test_event_driven_pdos_without_sync(bench: Callable[..., Bench]) -> None:
    motor = MotorConfig("left", "cia402", 3, options={"sync": False, "event_timer_ms": 10})
    b = bench([motor])
    assert b.enable([0.0])
    sim = b.sims[0]
    assert sim.object_value(0x1403, 2) == 255 and sim.object_value(0x1802, 5) == 10
    b.run(0.5, [20.0])
    assert not any(f.arbitration_id == 0x080 for f in b.sent)
    assert sim.syncs == 0 and sim.wheel_velocity_rad_s == pytest.approx(20.0, abs=0.1)
    beats = [f for f in b.seen if f.arbitration_id == 0x703 and f.timestamp_s > b.t - 0.5]
    assert len(beats) == 5 and beats[-1].data == b"\x05"  # 100 ms, OPERATIONAL
    fb = b.drv.feedback(0)
    assert fb is not None and fb.velocity_rad_s == pytest.approx(20.0, abs=0.11)


def test_poll_alone_produces_sync_every_10_ms(bench: Callable[..., Bench]) -> None:
    b = bench([LEFT])
    b.run(0.1)
    assert sum(f.arbitration_id == 0x080 for f in b.sent) in (10, 11)


@pytest.mark.parametrize("start", [s for s in State if s is not State.FAULT_REACTION_ACTIVE],
                         ids=lambda s: s.name)
def test_enable_from_any_drive_state(bench: Callable[..., Bench], start: State) -> None:
    b = bench([LEFT])
    b.sims[0].state = start
    assert b.enable()
    assert b.drv.drive_state(0) is State.OPERATION_ENABLED


def test_emcy_fault_and_recover(bench: Callable[..., Bench]) -> None:
    b = bench([LEFT])
    assert b.enable([1.0])
    b.run(0.2, [1.0])
    b.sims[0].inject(SimFault.FAULT)
    assert b.run(0.1, [1.0], until=lambda: b.state() is DriveState.FAULT)
    status = b.drv.status(b.t)[0]
    assert DriveFault.OVER_CURRENT in status.faults
    assert "EMCY 0x2310 Continuous over-current" in status.detail
    assert 'node 3 ("left")' in status.detail
    assert b.drv.command([1.0], b.t) == [make_sync()]  # no RPDO while faulted
    # the fault is still active in the drive: the fault reset does not take
    b.send(b.drv.enable(b.t))
    assert b.run(1.0, until=lambda: b.drv.phase(0) is Phase.FAILED)
    status = b.drv.status(b.t)[0]
    assert "no transition FAULT -> SWITCH ON DISABLED" in status.detail
    assert "EMCY 0x2310" in status.detail and DriveFault.OVER_CURRENT in status.faults
    # cleared in the drive: enable resets the fault and arms again
    b.sims[0].clear(SimFault.FAULT)
    assert b.enable([1.0])
    status = b.drv.status(b.t)[0]
    assert (status.faults, status.detail) == (DriveFault.NONE, "")
    b.run(0.2, [1.0])
    assert b.sims[0].wheel_velocity_rad_s == pytest.approx(1.0, abs=0.01)


def test_statusword_fault_without_emcy(bench: Callable[..., Bench]) -> None:
    b = bench([LEFT])
    assert b.enable([0.0])
    b.drv.on_frame(Frame(0x383, make_tpdo(0x383, 0x0218, 0).data, timestamp_s=b.t))
    assert b.state() is DriveState.FAULT
    status = b.drv.status(b.t)[0]
    assert status.faults == DriveFault.CONTROLLER
    assert "statusword 0x0218 reports FAULT" in status.detail


def test_silence_goes_offline_and_back(bench: Callable[..., Bench]) -> None:
    # A SILENT simulator hears nothing either, the gateway's heartbeat included: a consumer
    # time (1 s) longer than the 0.3 s of silence keeps the drive from stopping by itself.
    b = bench([dataclasses.replace(LEFT, options={"controller_timeout_s": 1.0})])
    assert b.enable([0.0])
    b.sims[0].inject(SimFault.SILENT)
    b.run(0.2, [0.0])
    assert b.state() is DriveState.ENABLED  # within liveness_s = 0.25 s
    b.run(0.1, [0.0])
    assert b.state() is DriveState.OFFLINE
    b.sims[0].clear(SimFault.SILENT)
    b.run(0.05, [0.0])
    assert b.state() is DriveState.ENABLED


@pytest.mark.parametrize(
    ("sim_kwargs", "expected"),
    [
        ({"missing_objects": (0x1017,)},
         "SDO write of 100 to 0x1017:00 (producer heartbeat time) aborted: "
         "0x06020000 Object does not exist"),
        ({"supported_modes": 0x01},
         "SDO write of 3 to 0x6060:00 (modes of operation = profile velocity) aborted: "
         "0x06090030 Value range of parameter exceeded"),
        ({"mode_switch_delay_s": 5.0},
         "0x6061:00 (modes of operation display) reads 1, expected 3 within 0.5 s"),
    ],
)
def test_enable_failure_names_the_cause(
    bench: Callable[..., Bench], sim_kwargs: dict[str, object], expected: str
) -> None:
    b = bench([LEFT], **sim_kwargs)
    b.send(b.drv.enable(b.t))
    assert b.run(1.0, until=lambda: b.drv.phase(0) is Phase.FAILED)
    status = b.drv.status(b.t)[0]
    assert status.state is DriveState.FAULT
    assert status.detail == f'node 3 ("left"): {expected}'
    assert b.sims[0].nmt is NmtState.PRE_OPERATIONAL  # never started


def test_slow_mode_switch_is_waited_for(bench: Callable[..., Bench]) -> None:
    b = bench([LEFT], mode_switch_delay_s=0.05)
    b.send(b.drv.enable(b.t))
    b.run(0.04)
    assert b.state() is DriveState.ENABLING and b.drv.phase(0) is Phase.CONFIGURING
    assert b.run(0.5, until=lambda: b.state() is DriveState.ENABLED)
    assert b.drv.enable(b.t) == []  # already armed: nothing to do


def test_sdo_timeout_of_a_silent_node(bench: Callable[..., Bench]) -> None:
    b = bench([LEFT])
    b.sims[0].inject(SimFault.SILENT)
    b.send(b.drv.enable(b.t))
    assert b.state() is DriveState.OFFLINE
    assert b.run(1.0, until=lambda: b.drv.phase(0) is Phase.FAILED)
    status = b.drv.status(b.t)[0]
    assert status.faults == DriveFault.COMMUNICATION
    assert "no SDO response within 0.5 s to the write of 2147484931 to 0x1403:01" in status.detail


def test_transition_timeout(bench: Callable[..., Bench], monkeypatch: pytest.MonkeyPatch) -> None:
    b = bench([LEFT])
    monkeypatch.setattr(b.sims[0], "_apply_controlword", lambda cw: None)
    b.send(b.drv.enable(b.t))
    assert b.run(1.5, until=lambda: b.drv.phase(0) is Phase.FAILED)
    assert b.drv.status(b.t)[0].detail.endswith(
        "no transition SWITCH ON DISABLED -> READY TO SWITCH ON within 0.5 s after "
        "controlword 0x0006 (statusword 0x1260)")


def test_disable_brakes_then_shuts_down(bench: Callable[..., Bench]) -> None:
    b = bench([LEFT])
    assert b.enable([0.0])
    b.run(0.3, [30.0])
    frames = b.drv.disable(b.t)
    assert frames == [Frame(0x503, hexb("0F 00 00 00 00 00")), make_sync()]
    b.send(frames)
    sim, speed_at_shutdown = b.sims[0], None
    for _ in range(600):
        b.run(DT, [30.0])  # the loop keeps calling command(): ignored once disarmed
        if speed_at_shutdown is None and sim.state is not State.OPERATION_ENABLED:
            speed_at_shutdown = sim.model.velocity_rad_s
    assert sim.state is State.READY_TO_SWITCH_ON
    assert speed_at_shutdown is not None and abs(speed_at_shutdown) < TWO_PI / 60
    assert b.state() is DriveState.DISABLED and b.drv.phase(0) is Phase.IDLE


def test_drive_watchdog_fault(bench: Callable[..., Bench]) -> None:
    b = bench([LEFT], command_timeout_s=0.05)
    assert b.enable([0.0])
    assert b.run(0.2, None, until=lambda: b.state() is DriveState.FAULT)  # no command()
    status = b.drv.status(b.t)[0]
    assert DriveFault.WATCHDOG in status.faults and "RPDO timeout" in status.detail


@pytest.mark.parametrize(
    ("command", "expected"),
    [(NmtCommand.RESET_NODE, "rebooted (boot-up message)"),
     (NmtCommand.ENTER_PRE_OPERATIONAL, "heartbeat reports NMT PRE_OPERATIONAL")],
)
def test_nmt_change_while_armed(
    bench: Callable[..., Bench], command: NmtCommand, expected: str
) -> None:
    b = bench([LEFT])
    assert b.enable([0.0])
    b.send([make_nmt(command, 3)])
    assert b.run(0.3, [0.0], until=lambda: b.state() is DriveState.FAULT)
    status = b.drv.status(b.t)[0]
    assert expected in status.detail and DriveFault.COMMUNICATION in status.faults


# ===================================================================== canopen cross-checks


def _od(*entries: tuple[int, int, int]) -> canopen.ObjectDictionary:
    od = canopen.ObjectDictionary()  # type: ignore[no-untyped-call]
    for index, dtype, default in entries:
        var = canopen.objectdictionary.ODVariable(f"x{index:04X}", index, 0)
        var.data_type, var.access_type, var.default = dtype, "rw", default
        od.add_object(var)
    return od


def _recv(bus: can.BusABC, cob: int) -> Frame:
    for _ in range(200):
        msg = bus.recv(0.02)
        if msg is not None and msg.arbitration_id == cob:
            return Frame(cob, bytes(msg.data))
    raise AssertionError(f"no frame 0x{cob:03X}")


def test_our_sdo_client_frames_against_canopen_server(channel: str) -> None:
    net = canopen.Network()
    net.NOTIFIER_CYCLE = 0.02
    node = canopen.LocalNode(3, _od((0x6060, canopen.objectdictionary.INTEGER8, 1),
                                    (0x60FF, canopen.objectdictionary.INTEGER32, 0)))
    net.add_node(node)
    net.connect(interface="virtual", channel=channel)
    gw = can.Bus(interface="virtual", channel=channel)
    try:
        send_frames(gw, [make_sdo_download(3, 0x60FF, 0, -1000, DataType.INTEGER32)])
        ack = parse_sdo_response(_recv(gw, 0x583))
        assert (ack.command, ack.index) == (ServerCommand.INITIATE_DOWNLOAD, 0x60FF)
        assert node.get_data(0x60FF, 0) == (-1000).to_bytes(4, "little", signed=True)
        send_frames(gw, [make_sdo_upload(3, 0x6060, 0)])
        assert parse_sdo_response(_recv(gw, 0x583)).value(DataType.INTEGER8) == 1
        send_frames(gw, [make_sdo_upload(3, 0x2000, 0)])
        abort = parse_sdo_response(_recv(gw, 0x583))
        assert abort.abort_code == 0x06020000
    finally:
        gw.shutdown()
        net.disconnect()


def test_canopen_client_against_our_simulator(channel: str) -> None:
    # An instant device: canopen's client reads 0x6061 and 0x6041 right after each write,
    # within the few ms a drive takes to switch (the driver waits; this client does not).
    sim = Cia402Simulator(LEFT, state_delay_s=0.0, switch_on_delay_s=0.0, enable_delay_s=0.0,
                          mode_switch_delay_s=0.0)
    net = canopen.Network()
    net.NOTIFIER_CYCLE = 0.02
    with SimulatedControllers([sim], channel) as ctl:
        ctl.start()
        node = canopen.RemoteNode(3, canopen.ObjectDictionary())  # type: ignore[no-untyped-call]
        net.add_node(node)
        net.connect(interface="virtual", channel=channel)
        try:
            node.sdo.RESPONSE_TIMEOUT = 2.0
            node.sdo.download(0x6060, 0, b"\x03")
            assert node.sdo.upload(0x6061, 0) == b"\x03"
            assert node.sdo.upload(0x6502, 0) == (0x6D).to_bytes(4, "little")
            node.sdo.download(0x6040, 0, b"\x06\x00")
            assert node.sdo.upload(0x6041, 0)[0] & 0x6F == State.READY_TO_SWITCH_ON
            with pytest.raises(SdoAbortedError) as err:
                node.sdo.upload(0x2000, 0)
            assert err.value.code == 0x06020000
            with pytest.raises(SdoAbortedError) as err:
                node.sdo.download(0x6041, 0, b"\x00\x00")
            assert err.value.code == 0x06010002
            with pytest.raises(SdoAbortedError) as err:  # remap while the PDO is valid
                node.sdo.download(0x1A00, 0, b"\x00")
            assert err.value.code == 0x08000022
        finally:
            net.disconnect()
