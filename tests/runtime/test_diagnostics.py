"""The gateway's status as ROS 2 diagnostics (``gateway.runtime.diagnostics``): the level
and message of the gateway, the bus and each motor for every state that decides them, and any
status a ``DiagnosticArray`` that goes on the wire and comes back the same; and the daemon's
side, :class:`~gateway.runtime.remote.Remote` handing the live view, and the bridge with ROS 2
diagnostics, a report once a second and at a change of state."""

from __future__ import annotations

import dataclasses
import itertools
from typing import TYPE_CHECKING, Any

import pytest
from hypothesis import given

from gateway.config import load_config
from gateway.core.bridge_settings import BridgeSettings, Ros2Settings, ZenohSettings
from gateway.core.errors import EncodeError
from gateway.core.protection import Guard, ProtectionState
from gateway.core.status import BusErrorState, BusHealth, ControllerStop, GatewayStatus
from gateway.core.types import DriveFault, DriveState, GatewayState
from gateway.runtime import liveview
from gateway.runtime.bridge import bridge as bridge_module
from gateway.runtime.diagnostics import diagnostic_array, hardware_ids
from gateway.runtime.mailbox import Mailbox
from gateway.runtime.remote import DIAGNOSTICS_PERIOD_S, Remote
from gateway.wire.ros2 import (
    DiagnosticLevel,
    Time,
    decode_diagnostic_array,
    encode_diagnostic_array,
)
from tests.wire.status_samples import sample_status, statuses

if TYPE_CHECKING:
    from pathlib import Path

OK, WARN, ERROR = DiagnosticLevel.OK, DiagnosticLevel.WARN, DiagnosticLevel.ERROR
HARDWARE = {"left": "odrive node 1 on socketcan:can0"}


def by_name(status: GatewayStatus) -> dict[str, tuple[DiagnosticLevel, str]]:
    return {s.name: (s.level, s.message)
            for s in diagnostic_array(status, "wheelgate", HARDWARE, 0).status}


def test_the_sample_status_gateway_bus_and_motors() -> None:
    report = diagnostic_array(sample_status(), "wheelgate", HARDWARE, 1_700_000_000_250_000_000)
    assert report.header.stamp == Time(1_700_000_000, 250_000_000)
    gw, bus, left, right = report.status
    assert (gw.level, gw.name, gw.message, gw.hardware_id) == (OK, "wheelgate: gateway",
                                                               "running", "tb3")
    values = {v.key: v.value for v in gw.values}
    assert values["target"] == "vx 0.2 m/s, vy 0 m/s, wz 0.5 rad/s"
    assert values["loop rate"] == "199.9 Hz of 200 Hz"
    assert values["last error"] == "motor 'right' (odrive node 2) faulted"
    assert values["configuration"] == "/etc/wheelgate/robot.yaml (CRC-32 1c291ca3)"
    assert (bus.level, bus.name, bus.message, bus.hardware_id) == (
        OK, "wheelgate: CAN bus", "controller active", "virtual:wheelgate")
    assert {v.key: v.value for v in bus.values}["frames sent"] == "4000"
    assert (left.level, left.name, left.message, left.hardware_id) == (
        OK, "wheelgate: motor left", "enabled", "odrive node 1 on socketcan:can0")
    assert {v.key: v.value for v in left.values} == {
        "state": "enabled", "node id": "1", "faults": "", "detail": "",
        "feedback age": "2 ms", "position": "1.5 rad", "velocity": "6 rad/s",
        "controller stop": "configured 0.25 s (confirmed)"}
    assert (right.level, right.message, right.hardware_id) == (
        ERROR, "fault: over_temperature, encoder; MOTOR_OVERTEMP", "")
    assert {v.key: v.value for v in right.values}["position"] == "unknown"


@pytest.mark.parametrize(("state", "level"), [
    (GatewayState.DISABLED, OK), (GatewayState.ENABLING, OK), (GatewayState.RUNNING, OK),
    (GatewayState.ESTOP, WARN), (GatewayState.STOPPING, WARN), (GatewayState.FAULT, ERROR)])
def test_the_gateways_level_follows_its_state(state: GatewayState,
                                              level: DiagnosticLevel) -> None:
    got = by_name(sample_status(state=state, reason="why" if level else ""))
    assert got["wheelgate: gateway"] == (level, state.name.lower() + (": why" if level else ""))


@pytest.mark.parametrize(("health", "level", "message"), [
    (BusHealth(True, BusErrorState.WARNING, {}, ""), WARN, "controller warning"),
    (BusHealth(True, BusErrorState.PASSIVE, {}, ""), WARN, "controller passive"),
    (BusHealth(True, BusErrorState.BUS_OFF, {}, ""), ERROR, "controller bus-off"),
    (BusHealth(False, BusErrorState.ACTIVE, {}, ""), ERROR,
     "controller active; frames do not go out"),
    (None, OK, "health not reported"),
])
def test_the_buss_level_follows_its_controller(health: BusHealth | None,
                                               level: DiagnosticLevel, message: str) -> None:
    status = sample_status()
    status = dataclasses.replace(status, bus=dataclasses.replace(status.bus, health=health))
    assert by_name(status)["wheelgate: CAN bus"] == (level, message)


CONFIRMED = ControllerStop(Guard.CONFIGURED, 0.25, ProtectionState.CONFIRMED)


@pytest.mark.parametrize(("state", "age", "stop", "level", "message"), [
    (DriveState.DISABLED, 0.001, CONFIRMED, OK, "disabled"),
    (DriveState.ENABLING, 0.001, None, OK, "enabling"),
    (DriveState.OFFLINE, None, CONFIRMED, ERROR, "offline: no feedback yet"),
    (DriveState.OFFLINE, 0.75, CONFIRMED, ERROR, "offline: no feedback for 0.75 s"),
    (DriveState.FAULT, 0.001, CONFIRMED, ERROR, "fault"),
    (DriveState.ENABLED, 0.001, ControllerStop(Guard.CONFIGURED, 0.25, ProtectionState.FAILED),
     ERROR, "enabled; its controller-side stop could not be configured: it will not stop by "
            "itself if wheelgate dies"),
    (DriveState.ENABLED, 0.001, ControllerStop(Guard.NONE, None,
                                               ProtectionState.NOT_APPLICABLE),
     WARN, "enabled; no known controller-side stop: it may keep running if wheelgate dies"),
    (DriveState.ENABLED, 0.001, ControllerStop(Guard.UNSTATED, None,
                                               ProtectionState.NOT_APPLICABLE),
     WARN, "enabled; no known controller-side stop: it may keep running if wheelgate dies"),
    (DriveState.ENABLED, 0.001, ControllerStop(Guard.STATED, 1.0,
                                               ProtectionState.NOT_APPLICABLE), OK, "enabled"),
])
def test_a_motors_level_follows_its_state_and_its_controller_side_stop(
        state: DriveState, age: float | None, stop: ControllerStop | None,
        level: DiagnosticLevel, message: str) -> None:
    status = sample_status()
    motor = dataclasses.replace(status.motors[0], state=state, feedback_age_s=age,
                                faults=DriveFault.NONE, detail="", controller_stop=stop)
    assert by_name(dataclasses.replace(status, motors=(motor,)))["wheelgate: motor left"] == (
        level, message)


@given(statuses())
def test_any_status_is_a_report_that_goes_on_the_wire(status: GatewayStatus) -> None:
    """One status for the gateway, one for the bus, one per motor; every text goes out and
    comes back (the model's texts are the gateway's own, never with a NUL; drawn ones may)."""
    report = diagnostic_array(status, "wheelgate", {}, 5)
    assert len(report.status) == 2 + len(status.motors)
    try:
        payload = encode_diagnostic_array(report)
    except EncodeError as err:  # (only a NUL in a drawn text may refuse)
        assert "expected no NUL" in str(err), err
        return
    assert decode_diagnostic_array(payload) == report


def test_each_motors_hardware_id_names_its_driver_node_and_bus() -> None:
    config = load_config(None)  # the embedded default: four ODrives on the virtual bus
    ids = hardware_ids(config)
    assert ids == {m.wheel: f"odrive node {m.node_id} on virtual:{config.bus.channel}"
                   for m in config.motors if m is not None}
    assert len(ids) == 4


class FakeWorker:
    """What :class:`Remote` needs of a live view or a bridge: its mailbox, start and close."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        self.mailbox: Any = Mailbox()

    def start(self) -> None:
        pass

    def close(self) -> None:
        pass


@pytest.mark.parametrize("worker", ["live view", "bridge"])
def test_the_daemon_hands_a_worker_a_report_each_second_and_at_a_change_of_state(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path, worker: str) -> None:
    """The schedule on a clock of the test's own; the bridge's ROS 2 diagnostics publish what
    its worker takes from this mailbox (``test_bridge_ros2.py`` reads them from a ROS node)."""
    workers: list[FakeWorker] = []

    def make_worker(*args: object, **kwargs: object) -> FakeWorker:
        workers.append(FakeWorker())
        return workers[-1]

    config = load_config()
    if worker == "bridge":
        monkeypatch.setattr(bridge_module, "Bridge", make_worker)
        ros2 = Ros2Settings(diagnostics="/diagnostics")
        config = dataclasses.replace(config, bridge=BridgeSettings(ZenohSettings(), "robot",
                                                                   ros2=ros2))
        record_mcap = ""
    else:
        monkeypatch.setattr(liveview, "LiveView", make_worker)
        record_mcap = str(tmp_path / "x.mcap")

    class Gw:
        state = GatewayState.RUNNING

    gw: Any = Gw()
    gw.config = config
    status: Any = itertools.count(1).__next__  # (each report a number: which one went where)

    latch: Any = None  # (nothing here sets it)
    remote = Remote(gw, latch, status, [], record_mcap=record_mcap)
    [taker] = workers
    taken: list[tuple[float, Any]] = []

    def at(now_s: float) -> None:
        remote.post((), now_s)
        report = taker.mailbox.take(0.0).report
        if report is not None:
            taken.append((now_s, report))

    for k in range(25):  # 2.5 s at 10 Hz
        at(10.0 + 0.1 * k)
    gw.state = GatewayState.ESTOP
    at(12.5)
    at(12.55)  # (the same state again: nothing)
    assert [round(t, 2) for t, _ in taken] == [10.0, 11.0, 12.0, 12.5]
    assert [r for _, r in taken] == [1, 2, 3, 4]
    assert DIAGNOSTICS_PERIOD_S == 1.0
