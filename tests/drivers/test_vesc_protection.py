"""A VESC at its factory settings, and what the configuration states about it (issue 14).

The firmware facts (https://github.com/vedderb/bldc, read at ``b9d287b3``): the app
configuration's ``timeout_msec`` is 1000 ms and ``timeout_brake_current`` 0 A
(``applications/appconf_default.h``; ``timeout.c`` releases the motor), ``can_status_msgs_r1``
is 0, so no status message goes out (``applications/appconf_default.h``,
``cancom_status_thread`` in ``comm/comm_can.c``), and ``s_pid_min_erpm`` is 900
(``motor/mcconf_default.h``): below it ``mcpwm_foc_set_pid_speed`` does not start a stopped
motor and the FOC interrupt brakes a running one at duty 0 (``motor/mcpwm_foc.c``).
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

import pytest
import yaml

from drivers.vesc import VescDriver
from drivers.vesc.codec import VescStatus, decode, make_set_current, make_set_rpm
from drivers.vesc.min_erpm import describe_band, in_band
from drivers.vesc.settings import STATUS_1, STATUS_5, TIMEOUT_FIX
from drivers.vesc.sim import SimMode, VescSimulator, simulator_for
from gateway.config import parse_config
from gateway.core.protection import Guard, ProtectionState
from gateway.core.types import DriveState
from gateway.drive.driveset import DriveSet
from tests.conftest import CONFIG_DIR
from tests.drivers.test_drivers_vesc import PP, motor
from tests.drivers.test_vesc_helpers import enabled

if TYPE_CHECKING:
    from gateway.core.types import Frame

#: eRPM per wheel rad/s of :func:`motor` (gear 1, 7 pole pairs).
ERPM_PER_RAD_S = 60.0 / (2.0 * math.pi) * PP
VESC_CONFIGS = ["differential_tub.yaml", "skid_steer.yaml", "ackermann.yaml"]


def run(sim: VescSimulator, start: float, stop: float, *, erpm: int | None = None,
        dt: float = 0.002) -> list[Frame]:
    """Tick ``sim`` from ``start`` to ``stop``; send SET_RPM ``erpm`` every step if given."""
    out: list[Frame] = []
    for k in range(round((stop - start) / dt)):
        t = start + (k + 1) * dt
        if erpm is not None:
            sim.handle(make_set_rpm(sim.node_id, erpm), t)
        out += sim.tick(t)
    return out


def wheel_erpm(sim: VescSimulator) -> float:
    """The simulated motor's true speed in eRPM (gear 1)."""
    return sim.wheel_velocity_rad_s * ERPM_PER_RAD_S


# ============================================================================ status messages


def test_a_factory_vesc_sends_no_status() -> None:
    sim = VescSimulator(motor(23))  # factory: can_status_msgs_r1 = 0
    assert run(sim, 0.0, 2.0, erpm=3000) == []
    assert wheel_erpm(sim) == pytest.approx(3000, abs=1)  # it drives all the same
    # Built from a block that does not state a status rate: the factory device.
    assert run(simulator_for(motor(23)), 0.0, 1.0) == []


@pytest.mark.parametrize(("rate", "msgs"), [(50.0, STATUS_1 | STATUS_5), (20.0, STATUS_1)])
def test_a_stated_status_rate_is_what_the_simulator_sends(rate: float, msgs: int) -> None:
    sim = simulator_for(motor(23, status_rate_hz=rate))
    frames = [decode(f) for f in run(sim, 0.0, 1.0)]
    assert sum(isinstance(f, VescStatus) for f in frames) == rate
    assert len(frames) == 2 * rate  # STATUS and STATUS_5
    only = VescSimulator(motor(23), status_msgs=msgs, status_rate_hz=rate)
    assert len(run(only, 0.0, 1.0)) == rate * bin(msgs).count("1")


def test_a_silent_vesc_is_offline_and_its_detail_says_how_to_enable_status() -> None:
    drv = VescDriver([motor(23)])
    sim = VescSimulator(motor(23))  # factory
    for f in drv.enable(0.0):
        for r in sim.handle(f, 0.0):
            drv.on_frame(r.stamped(0.0))
    for k in range(100):
        t = k * 0.01
        for f in drv.poll(t):
            sim.handle(f, t)
        for f in sim.tick(t):
            drv.on_frame(f.stamped(t))
    status = drv.status(1.0)[0]
    assert status.state is DriveState.OFFLINE
    assert "a VESC sends CAN status only when enabled in VESC Tool" in status.detail
    assert "Can Messages Rate 1" in status.detail
    assert "status_rate_hz" in status.detail
    # The FOC wizard's setting: Status 1 to 4, no STATUS_5 (conf_general.c).
    sim.status_msgs = 0b00001111
    for f in sim.tick(1.1):
        drv.on_frame(f.stamped(1.1))
    status = drv.status(1.1)[0]
    assert status.state is DriveState.OFFLINE
    assert status.detail.startswith("no STATUS_5 received")
    assert "Status 1 to 4 only" in status.detail
    sim.status_msgs = STATUS_1 | STATUS_5
    for f in sim.tick(1.2):
        drv.on_frame(f.stamped(1.2))
    assert drv.status(1.2)[0].state is DriveState.ENABLED
    assert drv.status(1.2)[0].detail == ""


# ============================================================================ timeout


@pytest.mark.parametrize(("stated", "timeout_s"), [(0.0, 1.0), (0.3, 0.3)])
def test_the_wheel_coasts_only_after_the_vesc_timeout(stated: float, timeout_s: float) -> None:
    # Not stated (0): the simulator has the factory 1 s; stated: what was set in VESC Tool.
    m = motor(23, status_rate_hz=50.0, controller_timeout_s=stated)
    drv, sim = VescDriver([m]), simulator_for(m)
    speed = 3000 / ERPM_PER_RAD_S  # wheel rad/s
    t, dt = 0.0, 0.002
    for f in drv.enable(t):  # the request of its timeout; the reply
        for r in sim.handle(f, t):
            drv.on_frame(r.stamped(t))
    # Read back: as stated (CONFIRMED), or, not stated, shown as read.
    assert drv.protection_state(0) is (
        ProtectionState.CONFIRMED if stated else ProtectionState.NOT_APPLICABLE)
    assert drv.protection(0).timeout_s == timeout_s
    while t < 1.0:  # the gateway commands, then dies at t = 1.0
        t += dt
        for f in drv.poll(t) + drv.command([speed], t):
            sim.handle(f, t)
        sim.tick(t)
    last = t
    truth = []  # (time since the last frame, the simulator's own state)
    while t < last + timeout_s + 0.3:
        t += dt
        sim.tick(t)
        truth.append((t - last, sim.model.armed, sim.wheel_velocity_rad_s))
    before = [v for age, _, v in truth if age < timeout_s - dt / 2]
    assert all(armed for age, armed, _ in truth if age < timeout_s - dt / 2)
    assert min(before) == pytest.approx(speed, rel=1e-3)  # still driven, at speed
    after = [(armed, v) for age, armed, v in truth if age > timeout_s + dt / 2]
    assert not any(armed for armed, _ in after)  # released: it coasts
    assert after[-1][1] == pytest.approx(0.0, abs=1e-3)
    assert mode_is(sim, SimMode.RELEASED)


def mode_is(sim: VescSimulator, mode: SimMode) -> bool:
    """Whether the simulator is in ``mode`` (a call, so mypy does not narrow between steps)."""
    return sim.mode is mode


# ============================================================================ minimum ERPM


@pytest.mark.parametrize("erpm", [500, -500, 899])
def test_a_stopped_motor_given_less_than_min_erpm_stays_stopped(erpm: int) -> None:
    sim = VescSimulator(motor(23))  # factory: s_pid_min_erpm 900
    run(sim, 0.0, 1.0, erpm=erpm)
    assert mode_is(sim, SimMode.RELEASED)
    assert not sim.model.armed
    assert sim.wheel_velocity_rad_s == 0.0
    run(sim, 1.0, 1.5, erpm=900)  # at s_pid_min_erpm it starts
    assert mode_is(sim, SimMode.SPEED)
    assert wheel_erpm(sim) == pytest.approx(900, abs=1)


def test_a_running_motor_given_less_than_min_erpm_is_braked() -> None:
    sim = VescSimulator(motor(23), status_msgs=STATUS_1)
    run(sim, 0.0, 0.5, erpm=3000)
    assert wheel_erpm(sim) == pytest.approx(3000, abs=1)
    frames = run(sim, 0.5, 1.5, erpm=500)
    assert mode_is(sim, SimMode.BELOW_MIN_ERPM)
    assert sim.model.armed  # braked (phases shorted), not released
    assert wheel_erpm(sim) == pytest.approx(0.0, abs=0.5)  # not 500
    last = decode(frames[-1])
    assert isinstance(last, VescStatus)
    assert (last.erpm, last.duty) == (0, 0.0)  # duty 0
    run(sim, 1.5, 2.0, erpm=2000)  # above it again: speed control
    assert mode_is(sim, SimMode.SPEED)
    assert wheel_erpm(sim) == pytest.approx(2000, abs=1)


def test_a_coasting_motor_given_less_than_min_erpm_coasts_on() -> None:
    sim = VescSimulator(motor(23))
    run(sim, 0.0, 0.5, erpm=3000)
    sim.handle(make_set_current(23, 0.0), 0.5)  # released, still turning
    sim.handle(make_set_rpm(23, 500), 0.5)
    assert mode_is(sim, SimMode.RELEASED)  # not started, so not braked either
    assert not sim.model.armed


def test_a_kinder_vesc_speed_controls_500_erpm() -> None:
    # s_pid_min_erpm lowered to 0 (VESC Tool: Minimum ERPM), as a sensored setup may.
    sim = VescSimulator(motor(23), min_erpm=0.0)
    run(sim, 0.0, 0.5, erpm=500)
    assert mode_is(sim, SimMode.SPEED)
    assert wheel_erpm(sim) == pytest.approx(500, abs=1)


# ============================================================================ the driver's band


def test_commands_in_the_band_go_out_as_they_are_and_are_counted() -> None:
    drv = VescDriver([motor(23), motor(24, wheel="right", min_erpm=0.0)])
    enabled(drv, 0.0)
    w500 = 500 / ERPM_PER_RAD_S
    assert drv.command([w500, w500], 0.01) == [make_set_rpm(23, 500), make_set_rpm(24, 500)]
    assert drv.command_counts["below_min_erpm"] == 1  # not the right one: it states 0
    drv.command([-w500, 0.0], 0.02)
    assert drv.command_counts["below_min_erpm"] == 2
    for speed in (0.0, 900 / ERPM_PER_RAD_S, -2000 / ERPM_PER_RAD_S):
        drv.command([speed, w500], 0.03)  # zero (a stop) and 900 are speed-controlled
    assert drv.poll(0.1) == [make_set_rpm(23, -2000), make_set_rpm(24, 500)]
    assert drv.command_counts["below_min_erpm"] == 2  # resends are not counted
    assert not drv.rejected  # not a rejected frame


def test_the_band_is_logged_at_most_once_per_5_s(caplog: pytest.LogCaptureFixture) -> None:
    drv = VescDriver([motor(23)])
    enabled(drv, 0.0)
    w500 = 500 / ERPM_PER_RAD_S
    with caplog.at_level(logging.WARNING, logger="drivers.vesc.driver"):
        for k in range(1000):  # 10 s at 100 Hz
            drv.command([w500], k * 0.01)
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 2  # at 0 s and at 5 s
    assert lines[0] == (
        "VESC 23 ('left'): SET_RPM 500 is below min_erpm 900: the VESC does not speed-control "
        "it (s_pid_min_erpm): a stopped motor stays stopped, a running one brakes to a stop"
    )
    assert lines[1].endswith("(499 more such commands since the last line)")
    assert drv.command_counts["below_min_erpm"] == 1000


def test_uncontrolled_band_per_motor() -> None:
    drv = VescDriver([
        motor(23, gear_ratio=5.0),
        motor(24, wheel="right", gear_ratio=5.0, invert=True, min_erpm=300.0),
        motor(25, wheel="third", min_erpm=0.0),
    ])
    for i, min_erpm in ((0, 900.0), (1, 300.0)):  # the inverted one's band is positive too
        lo, hi = drv.uncontrolled_band(i) or (math.nan, math.nan)
        assert lo == 0.0
        assert hi == pytest.approx(min_erpm / (5.0 * ERPM_PER_RAD_S))
    assert drv.uncontrolled_band(2) is None
    # Its edge is where the driver starts counting (up to the half eRPM of rounding).
    for i in (0, 1):
        band = drv.uncontrolled_band(i)
        assert band is not None
        min_erpm = (900.0, 300.0)[i]
        assert in_band(drv.erpm_for(i, -band[1] * 0.99), min_erpm)
        assert not in_band(drv.erpm_for(i, band[1] * 1.01), min_erpm)


def test_a_motor_whose_every_speed_is_in_the_band_is_doubted() -> None:
    """A VESC whose minimum ERPM lies above the motor's max_rpm speed-controls nothing the
    gateway may command (``init --driver vesc`` on a slow-wheeled robot gave one): ``check``
    and ``run`` warn, naming the keys; a band below max_rpm is no doubt."""
    # 7 pole pairs, 900 eRPM: 128.6 motor rpm; max_rpm 100 is inside the band, 3000 is not.
    drv = VescDriver([motor(23, max_rpm=100.0), motor(24, wheel="right", max_rpm=3000.0),
                      motor(25, wheel="third", max_rpm=100.0, min_erpm=0.0)])
    assert drv.doubts() == (
        "motor 'left': its VESC speed-controls no speed it may be commanded: max_rpm 100 is "
        "10.5 rad/s at the wheel, and below 13.5 rad/s (min_erpm 900 with pole_pairs 7 and "
        "gear_ratio 1) the VESC does not run its speed controller; lower s_pid_min_erpm on "
        "the VESC (VESC Tool) and min_erpm here, or check pole_pairs, gear_ratio and max_rpm",)


def test_the_shipped_vesc_robots_state_their_vesc_and_report_the_band() -> None:
    bands = {}
    for name in VESC_CONFIGS:
        raw = yaml.safe_load((CONFIG_DIR / name).read_text())
        cfg = parse_config(raw, name)
        assert not [w for w in cfg.warnings if "VESC" in w], cfg.warnings  # (no doubt either)
        radius = float(cfg.geometry["wheel_radius"])  # type: ignore[arg-type]
        for drv, _ in DriveSet(cfg).groups:
            if not isinstance(drv, VescDriver):
                continue
            for i, m in enumerate(drv.motors):
                prot = drv.protection(i)
                assert (prot.guard, prot.timeout_s) == (Guard.STATED, 1.0)
                band = drv.uncontrolled_band(i)
                assert band is not None
                bands[name, m.wheel] = describe_band(m.wheel, band[1], 900.0, radius)
    # The tub's 5:1 gear and 7 pole pairs: 900 eRPM is 2.69 rad/s at its wheels.
    assert bands["differential_tub.yaml", "left"] == (
        "wheel 'left': |speed| below 0.27 m/s (2.69 rad/s) is not speed-controlled by the VESC "
        "(s_pid_min_erpm 900): a stopped motor stays stopped, a running one brakes to a stop"
    )
    assert "below 0.09 m/s (0.898 rad/s)" in bands["skid_steer.yaml", "front_left"]
    assert "below 0.16 m/s (1.35 rad/s)" in bands["ackermann.yaml", "rear_left"]


# ============================================================================ protection


def test_an_unstated_timeout_is_unstated_with_a_warning_and_a_stated_one_is_stated() -> None:
    raw = yaml.safe_load((CONFIG_DIR / "differential_tub.yaml").read_text())
    del raw["motor_defaults"]["controller_timeout_s"]
    cfg = parse_config(raw, "tub.yaml")
    warned = [w for w in cfg.warnings if "controller watchdog" in w]
    assert len(warned) == 2  # one per wheel
    assert "1000 ms from the factory" in warned[0]
    assert "which wheelgate reads back from the VESC while enabling" in warned[0]
    assert warned[0].endswith(f"fix: {TIMEOUT_FIX}")
    assert "App Settings > General > Timeout in VESC Tool" in TIMEOUT_FIX
    drv = VescDriver([motor(23)])
    prot = drv.protection(0)
    assert (prot.guard, prot.timeout_s) == (Guard.UNSTATED, None)
    prot = VescDriver([motor(23, controller_timeout_s=1.0)]).protection(0)
    assert (prot.guard, prot.timeout_s) == (Guard.STATED, 1.0)
    assert prot.action == "releases the motor: it coasts (timeout_brake_current 0 A)"
    assert "VESC" in VescDriver.PROTOCOL
