"""A configuration against its bus (:mod:`gateway.config.budget`): a bitrate the controllers
cannot talk at and frames the bus cannot carry are refused by ``check`` and ``run``; a load
above 70 % (worst-case stuffing) is a warning; ``check`` lists every periodic stream."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest
import yaml

from gateway.cli import main
from gateway.config import load_config
from gateway.config.budget import bus_budget, check_bus
from gateway.core.errors import ConfigError
from gateway.drive.driveset import DriveSet
from tests.conftest import CONFIG_DIR

if TYPE_CHECKING:
    from pathlib import Path

    from click.testing import CliRunner

SHIPPED = sorted(p.name for p in CONFIG_DIR.glob("*.yaml"))


def _variant(tmp_path: Path, name: str, **changes: dict[str, object]) -> str:
    """A shipped config with some blocks updated, written beside its DBC and endpoints."""
    raw = yaml.safe_load((CONFIG_DIR / name).read_text())
    for block, values in changes.items():
        raw.setdefault(block, {}).update(values)
    out = tmp_path / name
    for extra in CONFIG_DIR.iterdir():  # (relative files: a DBC)
        if extra.suffix == ".dbc":
            (tmp_path / extra.name).write_bytes(extra.read_bytes())
    out.write_text(yaml.safe_dump(raw))
    return str(out)


def _check(path: str | None) -> list[str]:
    cfg = load_config(path)
    return check_bus(cfg, DriveSet(cfg))


@pytest.mark.parametrize("name", [None, *SHIPPED])
def test_the_shipped_robots_fit_their_buses(name: str | None) -> None:
    assert _check(None if name is None else str(CONFIG_DIR / name)) == []


def test_dji_escs_talk_at_1_mbit_only(tmp_path: Path) -> None:
    path = _variant(tmp_path, "mecanum.yaml", bus={"bitrate": 500_000})
    with pytest.raises(ConfigError) as err:
        _check(path)
    assert str(err.value) == (f"{path}: bus.bitrate: expected 1000000 bit/s, the only bitrate "
                              f"of the DJI controllers (fixed in them), got 500000")


def test_frames_the_bus_cannot_carry_are_refused(tmp_path: Path) -> None:
    # Two ODrives at 250 kbit/s (their factory bitrate) with a 1 kHz loop: 2000 Set_Input_Vel
    # a second alone need 88.8 %; with the estimates, heartbeats and odometry 103.5 %.
    path = _variant(tmp_path, "turtlebot3_burger.yaml", gateway={"rate_hz": 1000})
    with pytest.raises(ConfigError) as err:
        _check(path)
    text = str(err.value)
    assert text.startswith(f"{path}: bus.bitrate: the configuration's periodic frames need "
                           f"103.5 % of the 250 kbit/s bus without a single stuff bit (125.8 % "
                           f"with the most), so they could not all be sent (2000/s "
                           f"Set_Input_Vel, 200/s Get_Encoder_Estimates, ")
    # The rate that brings the worst case to 70 %: 250 kbit/s * 0.7 = 175,000 bit/s, of which
    # the controllers' and the odometry's 220 + 110 frames take 44,550; 2 frames a cycle of
    # 135 bits: (175000 - 44550) / 270 = 483.1 Hz.
    assert text.endswith("expected under 100 %: gateway.rate_hz below 483, lower feedback "
                         "rates, a higher bitrate (every node of the bus set to it), or the "
                         "motors over two buses")


def test_a_load_above_70_percent_is_a_warning(tmp_path: Path) -> None:
    path = _variant(tmp_path, "turtlebot3_burger.yaml", gateway={"rate_hz": 500})
    assert _check(path) == [
        f"{path}: bus.bitrate: the configuration's periodic frames need 59.1-71.8 % of 250 "
        f"kbit/s (1330 frames/s: gateway 1110, controllers 220), above 70 % with worst-case "
        f"bit stuffing: the frames of the highest identifiers wait for arbitration and error "
        f"frames have no room; fix: gateway.rate_hz below 483, lower feedback rates, a higher "
        f"bitrate (every node of the bus set to it), or the motors over two buses (`wheelgate "
        f"check` lists every stream)"]


def test_what_a_driver_cannot_know_is_listed_not_guessed(tmp_path: Path) -> None:
    raw = yaml.safe_load((CONFIG_DIR / "skid_steer.yaml").read_text())
    raw["motor_defaults"].pop("status_rate_hz")
    raw["motor_defaults"]["liveness_s"] = 0.5
    path = tmp_path / "skid.yaml"
    path.write_text(yaml.safe_dump(raw))
    cfg = load_config(str(path))
    budget = bus_budget(cfg, DriveSet(cfg))
    assert budget.unknown == ("STATUS and STATUS_5 of 4 VESC(s) whose status_rate_hz is not "
                              "stated",)
    assert [s.name for s in budget.streams] == [
        "SET_RPM", "WG_Odom_Pose", "WG_Odom_Velocity", "WG_Status"]


def test_check_lists_the_streams_and_run_refuses_a_full_bus(
    runner: CliRunner, tmp_path: Path
) -> None:
    result = runner.invoke(main, ["check"])
    assert result.exit_code == 0, result.output
    assert ("bus load: 15.0-18.2 % of 1000 kbit/s (1350 frames/s: gateway 910, controllers "
            "440), nominal to worst-case bit stuffing; periodic frames:\n"
            "  gateway       800.0/s  Set_Input_Vel (8 B): every cycle (gateway.rate_hz 200)\n"
            ) in result.stdout
    full = _variant(tmp_path, "turtlebot3_burger.yaml", gateway={"rate_hz": 1000})
    for args in (["check", "-c", full], ["run", "-c", full, "--sim", "--duration", "0.1"]):
        result = runner.invoke(main, args)
        assert result.exit_code == 2, (args, result.output)
        assert result.stderr.startswith(f"Error: {full}: bus.bitrate: the configuration's "
                                        f"periodic frames need 103.5 %"), args
    high = _variant(tmp_path, "turtlebot3_burger.yaml", gateway={"rate_hz": 500})
    result = runner.invoke(main, ["check", "-c", high])
    assert result.exit_code == 0, result.output
    assert "warning:  " + high + ": bus.bitrate: the configuration's periodic" in result.stdout
    assert result.stdout.rstrip().endswith("ok, with 1 warning(s)")
