"""The ODrive axis watchdog as controller-side protection (:mod:`drivers.odrive.watchdog`).

What reaches the bus and the simulated axis is checked, not only what the driver believes:
the factory-default axis keeps turning when the host falls silent; the gateway sets the 0.6
watchdog over CAN and arms only after reading it back; a wrong firmware version gets nothing
written; ``controller_watchdog: warn`` arms anyway.
"""

from __future__ import annotations

import json
import logging
import struct
from typing import TYPE_CHECKING, Any, cast

import pytest

from drivers.odrive.driver import OdriveDriver
from drivers.odrive.enums import AxisState
from drivers.odrive.options import OdriveOptions
from drivers.odrive.sim import OdriveSimulator, simulator_for
from drivers.odrive.watchdog import WatchdogEndpoints, endpoints_from_options
from gateway.cli import main
from gateway.config import load_config
from gateway.core.errors import ConfigError
from gateway.core.protection import Guard, ProtectionState, WatchdogPolicy
from gateway.core.types import DriveFault, DriveState, Frame
from tests.conftest import CONFIG_DIR
from tests.drivers.odrive_helpers import ENDPOINTS, motor, rig

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner

    from gateway.core.types import MotorConfig
    from gateway.runtime.daemon import Daemon


def hx(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


def sim_for(m: MotorConfig) -> OdriveSimulator:
    return cast("OdriveSimulator", simulator_for(m))


# ----------------------------------------------------------------------------- golden frames


def test_setup_frames_golden() -> None:
    """Node 3, 11-bit: Get_Version 0x060 (DLC 0); RxSdo 0x064: opcode, u16 endpoint, reserved,
    value, as ``struct.pack('<BHB' + fmt, ...)`` in ODrive's ``can_param_access.py``."""
    drv = OdriveDriver(
        [motor(3, firmware="0.6", controller_timeout_s=0.25, watchdog_endpoints=ENDPOINTS)]
    )
    assert drv.enable(0.0) == [Frame(0x060, b"")]  # nothing is written before the version
    reply = Frame(0x060, hx("02 04 04 3A 00 06 0A 00"), timestamp_s=0.01)  # fw 0.6.10
    assert drv.on_frame(reply)
    assert drv.poll(0.01) == [
        Frame(0x064, hx("01 C8 00 00 00 00 80 3E")),  # watchdog_timeout (200) = 0.25 f32
        Frame(0x064, hx("01 C9 00 00 01")),  # enable_watchdog (201) = true
        Frame(0x064, hx("00 C8 00 00")),  # read watchdog_timeout
        Frame(0x064, hx("00 C9 00 00")),  # read enable_watchdog
    ]
    assert drv.protection_state(0) is ProtectionState.PENDING
    assert struct.pack("<BHBf", 1, 200, 0, 0.25) == hx("01 C8 00 00 00 00 80 3E")
    drv.on_frame(Frame(0x065, hx("00 C8 00 00 00 00 80 3E"), timestamp_s=0.02))
    assert drv.poll(0.02) == []  # only the timeout read back so far: not armed
    drv.on_frame(Frame(0x065, hx("00 C9 00 00 01"), timestamp_s=0.03))
    assert drv.protection_state(0) is ProtectionState.CONFIRMED
    frames = drv.poll(0.03)
    assert Frame(0x067, hx("08 00 00 00")) in frames or any(
        f.arbitration_id == 0x067 and f.data[0] == 8 for f in frames
    )


def test_a_late_reply_after_a_disable_changes_nothing() -> None:
    drv = OdriveDriver(
        [motor(3, firmware="0.6", controller_timeout_s=0.25, watchdog_endpoints=ENDPOINTS)]
    )
    drv.enable(0.0)  # Get_Version goes out
    drv.disable(0.01)
    # The version arrives after the disable, and it is not the endpoints' firmware (which
    # would fail a running setup): no setup runs any more, so nothing fails.
    assert drv.on_frame(Frame(0x060, hx("02 04 04 3A 00 06 09 00"), timestamp_s=0.02))
    assert drv.poll(0.02) == []
    assert drv.protection_state(0) is ProtectionState.PENDING
    assert not drv.faults(0) and drv.detail(0) == ""
    assert drv.rejected == {}
    # A malformed one is still counted.
    drv.on_frame(Frame(0x060, hx("02 04"), timestamp_s=0.03))
    assert drv.rejected == {"malformed": 1}


# ----------------------------------------------------------------------------- on the bus


def test_a_factory_default_axis_keeps_turning_when_the_host_falls_silent(channel: str) -> None:
    """The adversary's finding: the watchdog is off from the factory."""
    sim = OdriveSimulator(motor(3, firmware="0.6"))  # factory settings, nothing configured
    with rig(channel, [sim]) as r:
        r.send(r.drv.enable(r.t))
        r.speeds = [2.0]
        r.run(1.0)
        assert sim.wheel_velocity_rad_s == pytest.approx(2.0, rel=1e-3)
        r.run(3.0, talk=False)
        assert sim.axis_state is AxisState.CLOSED_LOOP_CONTROL
        assert sim.wheel_velocity_rad_s == pytest.approx(2.0, rel=1e-3)


@pytest.mark.parametrize("firmware", ["0.5", "0.6"])
def test_a_configured_axis_stops_by_itself_when_the_host_falls_silent(
    channel: str, firmware: str
) -> None:
    kw: dict[str, Any] = {"controller_timeout_s": 0.2}
    if firmware == "0.6":
        kw["watchdog_endpoints"] = ENDPOINTS
    m = motor(3, firmware=firmware, **kw)
    sim = sim_for(m)
    assert sim.watchdog_enabled is (firmware == "0.5")  # 0.6: the gateway sets it
    with rig(channel, [sim]) as r:
        r.send(r.drv.enable(r.t))
        r.speeds = [2.0]
        r.run(1.0)
        assert sim.watchdog_enabled
        assert sim.watchdog_timeout_s == pytest.approx(0.2)
        assert sim.wheel_velocity_rad_s == pytest.approx(2.0, rel=1e-3)
        r.run(0.15, talk=False)
        states = [sim.axis_state]  # within the timeout
        r.run(0.1, talk=False)
        states.append(sim.axis_state)  # expired: disarmed, the motor coasts
        assert states == [AxisState.CLOSED_LOOP_CONTROL, AxisState.IDLE]
        assert not sim.model.armed


def test_the_axis_is_not_armed_before_the_read_back(channel: str) -> None:
    """Endpoint IDs the axis does not answer: no Set_Axis_State reaches it, FAULT names the
    motor, the protocol and the fix (``controller_watchdog: required``, the default)."""
    wrong = WatchdogEndpoints("0.6.10", 301, 300)  # the axis knows other IDs
    m = motor(3, firmware="0.6", watchdog_endpoints=ENDPOINTS)
    sim = OdriveSimulator(m, endpoints=wrong)
    with rig(channel, [sim]) as r:
        r.send(r.drv.enable(r.t))
        r.speeds = [2.0]
        r.run(2.0)
        assert sim.axis_state is AxisState.IDLE
        assert not sim.watchdog_enabled
        (status,) = r.drv.status(r.t)
        assert r.drv.protection_state(0) is ProtectionState.FAILED
        assert (status.state, status.faults) == (DriveState.FAULT, DriveFault.WATCHDOG)
        assert "motor 'left' (ODrive node 3): controller watchdog not confirmed" in status.detail
        assert "after 4 writes, read back" in status.detail
        assert "fix: give flat_endpoints" not in status.detail  # configured: no fix line


def test_another_firmware_version_gets_nothing_written(channel: str) -> None:
    m = motor(3, firmware="0.6", watchdog_endpoints=ENDPOINTS)
    sim = OdriveSimulator(m, endpoints=WatchdogEndpoints("0.6.11", 201, 200))
    with rig(channel, [sim]) as r:
        r.send(r.drv.enable(r.t))
        r.run(1.0)
        assert (sim.watchdog_enabled, sim.watchdog_timeout_s) == (False, 0.0)
        assert sim.axis_state is AxisState.IDLE
        (status,) = r.drv.status(r.t)
        assert "reports firmware 0.6.11" in status.detail
        assert "nothing was written" in status.detail
        # No use waiting for it (the gateway faults at once); a new enable tries again.
        assert r.drv.enable_failed() == [0]
        r.send(r.drv.enable(r.t))
        assert r.drv.enable_failed() == []


def test_warn_policy_arms_anyway_with_a_warning(
    channel: str, caplog: pytest.LogCaptureFixture
) -> None:
    m = motor(3, firmware="0.6", watchdog_endpoints=ENDPOINTS)
    sim = OdriveSimulator(m, endpoints=WatchdogEndpoints("0.6.10", 301, 300))
    with rig(channel, [sim]) as r, caplog.at_level(logging.WARNING):
        r.drv.watchdog_policy = WatchdogPolicy.WARN
        r.send(r.drv.enable(r.t))
        r.speeds = [1.0]
        r.run(2.0)
        assert sim.axis_state is AxisState.CLOSED_LOOP_CONTROL
        assert r.state() is DriveState.ENABLED
        assert r.drv.enable_failed() == []
    assert "arming it anyway (gateway.controller_watchdog: warn)" in caplog.text


def test_a_read_back_other_than_written_fails(channel: str) -> None:
    class Stubborn(OdriveSimulator):
        """An axis that takes the timeout but keeps its watchdog disabled."""

        def _parameter_access(self, frame: Frame, cmd: int) -> list[Frame]:
            out = super()._parameter_access(frame, cmd)
            self.watchdog_enabled = False
            return out

    m = motor(3, firmware="0.6", watchdog_endpoints=ENDPOINTS)
    sim = Stubborn(m, endpoints=WatchdogEndpoints("0.6.10", 201, 200))
    with rig(channel, [sim]) as r:
        r.send(r.drv.enable(r.t))
        r.run(2.0)
        assert sim.axis_state is AxisState.IDLE
        (status,) = r.drv.status(r.t)
        assert "'enable_watchdog': False" in status.detail
        assert r.drv.enable_failed() == [0]


# ----------------------------------------------------------------------------- configuration


def _config(tmp_path: Path, motor_defaults: str, gateway: str = "") -> Path:
    path = tmp_path / "robot.yaml"
    path.write_text(
        "drive: differential\n"
        "geometry: {wheel_radius: 0.05, track: 0.3}\n"
        f"motor_defaults: {{driver: odrive, gear_ratio: 5.0, max_rpm: 3000, {motor_defaults}}}\n"
        "motors: {left: {node_id: 1}, right: {node_id: 2, invert: true}}\n"
        "bus: {interface: virtual, channel: watchdog}\n"  # said: no warning for a missing bus
        "limits: {max_wheel_accel_rad_s2: 30.0}\n"  # nor for missing limits
        + (f"gateway: {{{gateway}}}\n" if gateway else "")
    )
    return path


def test_config_0_6_without_endpoints_is_refused_under_required(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as err:
        load_config(str(_config(tmp_path, 'firmware: "0.6"')))
    text = str(err.value)
    assert "motor 'left' (odrive node 1): controller watchdog not set over CAN: the motor " \
        "block names no endpoint IDs" in text
    assert "gateway.controller_watchdog is required" in text
    assert "fix: give flat_endpoints" in text
    cfg = load_config(str(_config(tmp_path, 'firmware: "0.6"', "controller_watchdog: warn")))
    assert any("names no endpoint IDs" in w for w in cfg.warnings)


def test_config_0_5_states_the_watchdog_or_gets_the_warning(tmp_path: Path) -> None:
    cfg = load_config(str(_config(tmp_path, 'firmware: "0.5"')))
    assert len(cfg.warnings) == 2
    assert "watchdog_timeout = 0.25" in cfg.warnings[0]
    cfg = load_config(str(_config(tmp_path, 'firmware: "0.5", controller_timeout_s: 0.25')))
    assert cfg.warnings == ()
    drv = OdriveDriver([m for m in cfg.motors if m is not None])
    assert drv.protection(0).guard is Guard.STATED
    assert drv.protection(0).timeout_s == 0.25
    with pytest.raises(ConfigError, match=r"expected firmware 0\.6"):
        load_config(
            str(_config(tmp_path, 'firmware: "0.5", watchdog_endpoints: ' + json.dumps(ENDPOINTS)))
        )


def test_the_0_5_advice_is_odrivetool_syntax_per_node(tmp_path: Path) -> None:
    """What to type, as odrivetool takes it: the board object ``odrv0``, its axis, the two
    ``Axis.config`` attributes of firmware 0.5 (``Firmware/odrive-interface.yaml``), then the
    board's ``save_configuration()``; the node ID said apart, not spliced into the names."""
    cfg = load_config(str(_config(tmp_path, 'firmware: "0.5"')))
    fixes = [w.partition("; fix: ")[2] for w in cfg.warnings]
    assert fixes == [
        f"on the ODrive whose axis has CAN node {n}, in odrivetool: "
        f"odrv0.axis0.config.watchdog_timeout = 0.25; "
        f"odrv0.axis0.config.enable_watchdog = True; odrv0.save_configuration() "
        f"(axis1 for axis0 if odrv0.axis1.config.can.node_id is {n}); "
        f"then state controller_timeout_s: 0.25"
        for n in (1, 2)]
    for fix in fixes:
        said = fix.partition("odrivetool: ")[2].partition(" (")[0]
        for statement in said.split("; "):  # each one a Python statement on odrv0
            compile(statement, "odrivetool", "exec")
            assert statement.startswith("odrv0.")


def test_a_timeout_shorter_than_three_periods_is_warned(tmp_path: Path) -> None:
    cfg = load_config(
        str(_config(tmp_path, 'firmware: "0.5", controller_timeout_s: 0.01', "rate_hz: 200"))
    )
    assert any("expected at least three loop periods" in w for w in cfg.warnings)


def test_flat_endpoints_file(tmp_path: Path) -> None:
    doc = {
        "fw_version": "0.6.10-1",
        "hw_version": "4.4.58",
        "endpoints": {
            "axis0.config.enable_watchdog": {"id": 154, "type": "bool", "access": "rw"},
            "axis0.config.watchdog_timeout": {"id": 153, "type": "float", "access": "rw"},
        },
    }
    (tmp_path / "flat_endpoints.json").write_text(json.dumps(doc))
    here = str(tmp_path)
    ep = endpoints_from_options(
        OdriveOptions(flat_endpoints="flat_endpoints.json", config_dir=here), "m"
    )
    assert ep == WatchdogEndpoints("0.6.10", 154, 153, "4.4.58")
    doc["endpoints"]["axis0.config.watchdog_timeout"]["type"] = "uint32"  # type: ignore[index]
    (tmp_path / "flat_endpoints.json").write_text(json.dumps(doc))
    with pytest.raises(ConfigError, match=r"expected 'axis0\.config\.watchdog_timeout' of type"):
        endpoints_from_options(
            OdriveOptions(flat_endpoints="flat_endpoints.json", config_dir=here), "m"
        )
    with pytest.raises(ConfigError, match="cannot read"):
        endpoints_from_options(OdriveOptions(flat_endpoints="missing.json", config_dir=here), "m")
    with pytest.raises(ConfigError, match="got both"):
        endpoints_from_options(
            OdriveOptions(flat_endpoints="x.json", watchdog_endpoints=ENDPOINTS, config_dir=here),
            "m",
        )
    with pytest.raises(ConfigError, match="expected two different endpoint IDs"):
        endpoints_from_options(
            OdriveOptions(watchdog_endpoints={**ENDPOINTS, "watchdog_timeout": 201}), "m"
        )


# ----------------------------------------------------------------------------- reports


def test_status_shows_each_motors_confirmed_watchdog(
    runner: CliRunner, daemon: Daemon, sock_path: str
) -> None:
    """The TurtleBot3's two ODrives (the simulator's endpoints): set, read back, armed."""
    result = runner.invoke(main, ["status", "--socket", sock_path, "--json"])
    assert result.exit_code == 0, result.output
    motors = json.loads(result.output)["motors"]
    assert [m["controller_stop"] for m in motors] == [
        {"guard": "configured", "timeout_s": 0.25, "state": "confirmed"}
    ] * 2
    assert all(m["state"] == "enabled" for m in motors)
    assert daemon.sim is not None
    for sim in daemon.sim.simulators:
        assert isinstance(sim, OdriveSimulator)
        assert (sim.watchdog_enabled, sim.watchdog_timeout_s) == (True, 0.25)
    text = runner.invoke(main, ["status", "--socket", sock_path]).output
    assert "stop configured 0.25 s (confirmed)" in text


def test_check_prints_every_motors_protection(runner: CliRunner) -> None:
    result = runner.invoke(main, ["check", "-c", str(CONFIG_DIR / "turtlebot3_burger.yaml")])
    assert result.exit_code == 0, result.output
    assert "controller-side stop when wheelgate dies (controller_watchdog: required):" in (
        result.output
    )
    assert (
        "motor 'left' (odrive node 1): configured: stops 0.25 s after wheelgate falls silent "
        "(latches WATCHDOG_TIMER_EXPIRED and goes IDLE: the motor coasts); axis watchdog "
        "written over CAN (RxSdo endpoints 2, 1 of firmware 0.0.0) and read back before arming"
    ) in result.output
