"""Controller-side protection of DJI C620/C610 ESCs and DBC-described controllers (issue 14).

DJI: no public source says what the ESC does when the command frames stop, so wheelgate assumes
the worst -- it holds its last current for ever -- reports :attr:`Guard.NONE`, and refuses a
motor block that does not acknowledge it (``no_controller_stop: acknowledged``).  The simulator
holds its current too, never kinder than the assumption.

DBC: the controller's timeout cannot be set or read through a DBC file, so the motor block
states it (``controller_timeout_s``): :attr:`Guard.STATED`, else :attr:`Guard.UNSTATED` and a
warning.  The simulator stands for the user's controller: it stops the motor that long after the
last command frame, and with nothing stated holds the last command for ever.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import pytest
import yaml

from drivers.dbc import DbcDriver
from drivers.dbc.sim import DbcSimulator
from drivers.dji import M3508_GEAR_RATIO, DjiDriver
from drivers.dji.sim import DjiSimulator
from gateway.cli import main
from gateway.config import load_config, parse_config
from gateway.core.errors import ConfigError
from gateway.core.protection import Guard
from gateway.drive.driveset import DriveSet
from gateway.sim.registry import simulators_for
from tests import factories
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from collections.abc import Sequence

    from click.testing import CliRunner

    from gateway.core.types import MotorConfig
    from gateway.drive.driver import MotorDriver
    from gateway.sim.device import DeviceSimulator

MECANUM = CONFIG_DIR / "mecanum.yaml"
EXAMPLE_DBC = CONFIG_DIR / "example_dbc.yaml"
ACK = {"no_controller_stop": "acknowledged"}
#: Simulation step (s): the DJI ESCs' feedback period.
STEP_S = 0.001


def dji_motor(*, validate: bool = True, **options: object) -> MotorConfig:
    """A DJI C620 motor block of the factory (:func:`tests.factories.motor`), ESC 1."""
    return factories.motor("dji", 1, "front_left", gear_ratio=M3508_GEAR_RATIO, max_rpm=9000.0,
                           validate=validate, options={"esc": "c620", **options})


def doc_of(path: object) -> dict[str, object]:
    loaded = yaml.safe_load(CONFIG_DIR.joinpath(str(path)).read_text("utf-8"))
    assert isinstance(loaded, dict)
    return loaded


def run(
    drv: MotorDriver[Any],
    sims: Sequence[DeviceSimulator],
    t: float,
    until: float,
    setpoints: Sequence[float] | None,
) -> float:
    """Step the simulators every :data:`STEP_S` up to ``until``; the driver takes their frames
    and, unless ``setpoints`` is ``None`` (wheelgate is dead), commands them every step."""
    while t < until - 1e-9:
        t += STEP_S
        for frame in [f for s in sims for f in s.tick(t)]:
            drv.on_frame(frame.stamped(t))
        if setpoints is not None:
            for frame in drv.poll(t) + drv.command(setpoints, t):
                for s in sims:
                    s.handle(frame, t)
    return t


def wheel_speed(sim: DeviceSimulator) -> float:
    """The simulated wheel's speed (rad/s, wheel side, the sign of the motor block undone)."""
    return sim.model.velocity_rad_s / sim.motor.gear_ratio * sim.motor.sign


# ===================================================================== DJI: the acknowledgement


def test_dji_motor_without_the_acknowledgement_is_refused_naming_motor_consequence_and_fix() -> (
    None
):
    with pytest.raises(ConfigError) as info:
        DjiDriver([dji_motor(validate=False)])
    text = str(info.value)
    assert text.startswith("motor 'front_left'.no_controller_stop: expected 'acknowledged', got ")
    assert "got nothing" in text
    # The consequence: what happens when wheelgate dies.
    assert "no known command timeout" in text
    assert "hold its last current for ever" in text
    assert "if wheelgate dies (kill -9, out of memory, a frozen host)" in text
    assert "an unloaded wheel speeds up" in text
    # The fix: the hardware answer, then the key.
    assert "relay or an e-stop loop" in text
    assert "hardware watchdog" in text
    assert "add 'no_controller_stop: acknowledged' to this motor's block" in text


@pytest.mark.parametrize("value", ["yes", "Acknowledged", True, 1])
def test_dji_acknowledgement_must_be_exactly_the_word(value: object) -> None:
    with pytest.raises(ConfigError) as info:
        DjiDriver([dji_motor(validate=False, no_controller_stop=value)])
    text = str(info.value)
    assert text.startswith("motor 'front_left'.no_controller_stop: expected ")
    assert repr(value) in text


def test_dji_config_without_the_acknowledgement_is_refused_at_load_naming_file_and_motor() -> None:
    doc = doc_of("mecanum.yaml")
    defaults = doc["motor_defaults"]
    assert isinstance(defaults, dict)
    del defaults["no_controller_stop"]
    with pytest.raises(ConfigError) as info:
        parse_config(doc, "robot.yaml")
    assert str(info.value).startswith(
        "robot.yaml: motors.front_left.no_controller_stop: expected 'acknowledged', got nothing: "
    )


def test_dji_steering_actuator_needs_the_acknowledgement_too() -> None:
    doc = doc_of("swerve.yaml")
    steering = {"driver": "dji", "esc": "c610", "gear_ratio": 72.0, "max_rpm": 15000}
    doc["steering_defaults"] = steering
    doc["steering"] = {w: {"node_id": i + 1} for i, w in enumerate(
        ("front_left", "front_right", "rear_left", "rear_right"))}
    with pytest.raises(ConfigError, match=r"steering\.front_left\.no_controller_stop: expected"):
        parse_config(doc, "robot.yaml")
    steering.update(ACK)
    drives = DriveSet(parse_config(doc, "robot.yaml"))
    labelled = dict(drives.protections())
    prot = labelled["motor 'front_left steering' (dji node 1)"]
    assert prot.guard is Guard.NONE
    assert "this steering actuator keeps its torque and turns on" in prot.how


# ===================================================================== DJI: Guard.NONE


def test_acknowledged_dji_motor_has_no_controller_stop_and_the_config_warns() -> None:
    drv = DjiDriver([dji_motor(no_controller_stop="acknowledged")])
    assert drv.PROTOCOL == "DJI"
    prot = drv.protection(0)
    assert prot.guard is Guard.NONE
    assert prot.timeout_s is None
    assert "holds its last current" in prot.action
    assert prot.describe().startswith(
        "NONE: the C620/C610 ESC has no known command timeout and is assumed to hold its last "
        "current, and wheelgate runs the speed loop, so if wheelgate dies this wheel keeps its "
        "torque (unloaded, it speeds up) until the ESC's power is cut"
    )
    assert "hardware watchdog" in prot.fix
    # One warning per motor of the shipped robot, each naming its motor.
    cfg = load_config(MECANUM)
    for name, node in (("front_left", 1), ("front_right", 2), ("rear_left", 3),
                       ("rear_right", 4)):
        (warning,) = [w for w in cfg.warnings if f"motor '{name}' (dji node {node})" in w]
        assert warning == (
            f"{MECANUM}: motor '{name}' (dji node {node}): controller watchdog {prot.describe()}"
            f"; fix: {prot.fix}"
        )


def test_check_shows_the_dji_warning(runner: CliRunner) -> None:
    result = runner.invoke(main, ["check", "-c", str(MECANUM)])
    assert result.exit_code == 0, result.output
    out = result.output
    assert (
        f"warning:  {MECANUM}: motor 'front_left' (dji node 1): controller watchdog NONE: the "
        "C620/C610 ESC has no known command timeout and is assumed to hold its last current"
    ) in out
    assert out.count("controller watchdog NONE: ") == 4
    assert "ok, with 4 warning(s)" in out


def test_shipped_dji_configs_acknowledge_it() -> None:
    for name in ("mecanum.yaml", "omni_delta.yaml"):
        cfg = load_config(CONFIG_DIR / name)
        assert all(m is not None and m.options["no_controller_stop"] == "acknowledged"
                   for m in cfg.motors), name


# ===================================================================== DJI: the simulator


def test_dji_simulator_keeps_the_wheel_turning_when_the_commands_stop() -> None:
    """The assumption, in the simulator: a C620 holds its last current for ever, so when
    wheelgate falls silent the wheel keeps the torque of the last cycle and turns on."""
    cfg = load_config(MECANUM)
    drives = DriveSet(cfg)
    ((drv, _),) = drives.groups
    assert isinstance(drv, DjiDriver)
    sims = simulators_for(drives.all_motors())
    assert all(isinstance(s, DjiSimulator) and s.command_timeout_s is None for s in sims)
    target = 5.0  # wheel rad/s
    drv.enable(0.0)
    t = run(drv, sims, 0.0, 1.0, [target] * 4)
    assert all(wheel_speed(s) == pytest.approx(target, rel=0.05) for s in sims)
    held = [s.command_raw for s in sims if isinstance(s, DjiSimulator)]
    assert all(raw != 0 for raw in held)
    # wheelgate dies: no frame at all from here on.
    run(drv, sims, t, t + 3.0, None)
    assert [s.command_raw for s in sims if isinstance(s, DjiSimulator)] == held
    # (At the last cycle's current, whatever the speed loop's state then: the ESCs' feedback
    # at their own phases, the last currents differ by 10 %.)
    assert all(wheel_speed(s) == pytest.approx(target, rel=0.1) for s in sims)


# ===================================================================== DBC: stated or not


def dbc_doc(timeout: float | None) -> dict[str, object]:
    doc = doc_of("example_dbc.yaml")
    defaults = doc["motor_defaults"]
    assert isinstance(defaults, dict)
    defaults["dbc"] = str(CONFIG_DIR / "example_controller.dbc")
    if timeout is None:
        defaults.pop("controller_timeout_s", None)
    else:
        defaults["controller_timeout_s"] = timeout
    return doc


def test_dbc_stated_timeout_is_guard_stated() -> None:
    cfg = load_config(EXAMPLE_DBC)
    ((drv, _),) = DriveSet(cfg).groups
    assert isinstance(drv, DbcDriver)
    assert drv.PROTOCOL == "DBC"
    prot = drv.protection(0)
    assert (prot.guard, prot.timeout_s) == (Guard.STATED, 0.2)
    assert prot.describe().startswith("stated: stops 0.2 s after wheelgate falls silent (")
    assert not [w for w in cfg.warnings if "controller watchdog" in w]


@pytest.mark.parametrize("timeout", [None, 0.0])
def test_dbc_unstated_timeout_is_warned_about(timeout: float | None) -> None:
    cfg = parse_config(dbc_doc(timeout), "robot.yaml")
    ((drv, _),) = DriveSet(cfg).groups
    prot = drv.protection(1)
    assert (prot.guard, prot.timeout_s) == (Guard.UNSTATED, None)
    (warning,) = [w for w in cfg.warnings if "motor 'right'" in w]
    assert warning == (
        "robot.yaml: motor 'right' (dbc node 2): controller watchdog not stated: nothing known "
        "stops this DBC motor if wheelgate dies; fix: set a command timeout on the controller "
        "with its vendor's tool (a DBC file does not say how) and state it as "
        "controller_timeout_s in the motor block"
    )


def test_dbc_timeout_is_a_checked_number() -> None:
    doc = dbc_doc(None)
    doc["motors"] = {"left": {"node_id": 1, "controller_timeout_s": "soon"},
                     "right": {"node_id": 2, "controller_timeout_s": -1.0}}
    with pytest.raises(ConfigError, match=r"motors\.left\.controller_timeout_s: expected float"):
        parse_config(doc, "robot.yaml")
    doc["motors"]["left"]["controller_timeout_s"] = 0.2  # type: ignore[index]
    with pytest.raises(ConfigError, match=r"motors\.right\.controller_timeout_s: expected at "
                       r"least 0, got -1\.0"):
        parse_config(doc, "robot.yaml")


# ===================================================================== DBC: the simulator


def dbc_session(timeout: float | None) -> tuple[DbcDriver, list[DeviceSimulator], float]:
    """The example robot driven at 5 rad/s for a second by a live driver."""
    drives = DriveSet(parse_config(dbc_doc(timeout), "robot.yaml"))
    ((drv, _),) = drives.groups
    assert isinstance(drv, DbcDriver)
    sims = simulators_for(drives.all_motors())
    assert all(isinstance(s, DbcSimulator) for s in sims)
    for frame in drv.enable(0.0):
        for s in sims:
            s.handle(frame, 0.0)
    t = run(drv, sims, 0.0, 1.0, [5.0, 5.0])
    assert all(wheel_speed(s) == pytest.approx(5.0, rel=0.02) for s in sims)
    return drv, sims, t


def test_dbc_simulator_stops_the_wheel_its_stated_timeout_after_the_last_command() -> None:
    timeout, margin = 0.2, 0.1  # the margin: one step, and the model's 10 ms time constant
    drv, sims, t = dbc_session(timeout)
    assert all(isinstance(s, DbcSimulator) and s.command_timeout_s == timeout for s in sims)
    # wheelgate dies at t: the controllers hold the command until their timeout...
    t_dead = t
    t = run(drv, sims, t, t_dead + timeout - 0.01, None)
    assert all(wheel_speed(s) == pytest.approx(5.0, rel=0.02) for s in sims)
    # ... then stop the wheel within the margin, and it stays stopped.
    stopped_at: float | None = None
    while t < t_dead + timeout + 1.0:
        t = run(drv, sims, t, t + STEP_S, None)
        if stopped_at is None and all(abs(wheel_speed(s)) < 0.01 for s in sims):
            stopped_at = t
    assert stopped_at is not None
    assert stopped_at - t_dead <= timeout + margin
    assert all(abs(wheel_speed(s)) < 1e-3 for s in sims)


def test_dbc_simulator_keeps_turning_for_ever_with_no_timeout_stated() -> None:
    drv, sims, t = dbc_session(None)
    assert all(isinstance(s, DbcSimulator) and s.command_timeout_s == 0.0 for s in sims)
    run(drv, sims, t, t + 3.0, None)
    assert all(wheel_speed(s) == pytest.approx(5.0, rel=0.02) for s in sims)
    assert all(math.isfinite(s.model.position_rad) for s in sims)
