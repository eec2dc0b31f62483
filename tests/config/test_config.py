"""Configuration: every shipped file loads; bad files get precise messages."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import pytest
import yaml

from gateway.config import DEFAULT_NAME, load_config, parse_config
from gateway.core.errors import ConfigError
from gateway.core.settings import BusConfig, LoopConfig
from tests.conftest import CONFIG_DIR, REPO, SIM_ODRIVE_ENDPOINTS

if TYPE_CHECKING:
    from pathlib import Path

SHIPPED = sorted(CONFIG_DIR.glob("*.yaml"))


def test_every_seed_robot_ships_a_config() -> None:
    names = {p.stem for p in SHIPPED}
    assert {"turtlebot3_burger", "mecanum", "differential_tub", "differential_castor",
            "omni3_swedish", "omni_delta", "omni3", "synchro", "tricycle", "ackermann",
            "skid_steer", "swerve"} <= names


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_shipped_config_loads(path: Path) -> None:
    cfg = load_config(path)
    assert cfg.model.n == len(cfg.motors)
    assert any(m is not None for m in cfg.motors)


def test_turtlebot3_burger() -> None:
    cfg = load_config(CONFIG_DIR / "turtlebot3_burger.yaml")
    assert cfg.drive == "differential"
    assert [w.name for w in cfg.wheels] == ["left", "right"]
    assert cfg.geometry["wheel_radius"] == 0.033
    assert cfg.geometry["track"] == 0.160
    assert cfg.wheels[0].y == pytest.approx(0.08)


def test_mecanum_wheel_names() -> None:
    cfg = load_config(CONFIG_DIR / "mecanum.yaml")
    assert [w.name for w in cfg.wheels] == ["front_left", "front_right", "rear_left", "rear_right"]


def test_embedded_default_loads() -> None:
    cfg = load_config()
    assert cfg.source == DEFAULT_NAME
    assert cfg.model.mobility.mobility == 3


def test_motor_defaults_merge_and_limits() -> None:
    cfg = load_config(CONFIG_DIR / "turtlebot3_burger.yaml")
    left, right = cfg.motors
    assert left is not None and right is not None
    assert (left.driver, left.node_id, left.invert) == ("odrive", 1, False)
    assert (right.node_id, right.invert, right.max_rpm) == (2, True, 61.0)
    assert cfg.limits.max_wheel_rad_s[0] == pytest.approx(61 * 2 * math.pi / 60)


BASE = {
    "drive": "differential",
    "geometry": {"wheel_radius": 0.05, "track": 0.3},
    "motor_defaults": {"driver": "odrive", "max_rpm": 3000,
                       "watchdog_endpoints": SIM_ODRIVE_ENDPOINTS},
    "motors": {"left": {"node_id": 1}, "right": {"node_id": 2}},
}


def with_(path: str, value: object) -> dict[str, object]:
    doc = yaml.safe_load(yaml.safe_dump(BASE))
    node = doc
    keys = path.split(".")
    for k in keys[:-1]:
        node = node.setdefault(k, {})
    if value is ...:
        del node[keys[-1]]
    else:
        node[keys[-1]] = value
    return doc  # type: ignore[no-any-return]


@pytest.mark.parametrize(
    ("path", "value", "message"),
    [
        ("colour", "red", "robot.yaml: colour: unknown key (known top-level keys: bridge, bus, "
                          "drive, foxglove, gateway, "),
        ("drive", "hovercraft", "robot.yaml: drive: expected one of ackermann, differential, "),
        ("geometry.track", "wide", "robot.yaml: geometry.track: expected float, got 'wide'"),
        ("geometry.track", -0.3, "robot.yaml: geometry.track: expected at least 0.001 m, got -0.3"),
        ("geometry.track", 0.0, "robot.yaml: geometry.track: expected at least 0.001 m, got 0.0"),
        ("geometry.track", math.inf, "robot.yaml: geometry.track: expected a finite number, "
                                     "got inf"),
        ("geometry.track", ..., "robot.yaml: geometry.track: required key is missing"),
        ("geometry.wheelbase", 0.3, "robot.yaml: geometry.wheelbase: a differential drive has "
                                    "no 'wheelbase'; it is a key of ackermann, mecanum, "
                                    "skid_steer, swerve, tricycle drives (known differential "
                                    "geometry keys: track, wheel_radius)"),
        ("geometry.wheelbas", 0.3, "robot.yaml: geometry.wheelbas: a differential drive has no "
                                   "'wheelbase' ('wheelbas': did you mean 'wheelbase'?)"),
        ("geometry.whelradius", 0.3, "robot.yaml: geometry.whelradius: unknown key; did you "
                                     "mean 'wheel_radius'? (known differential geometry keys"),
        ("motors.left.node_id", "x", "robot.yaml: motors.left.node_id: expected int, got 'x'"),
        ("motors.left.node_id", 99, "robot.yaml: motors.left.node_id: expected int 0..62, got 99"),
        ("motors.left.node_id", 2, "share odrive node_id 2; expected unique node IDs"),
        ("motors.middle", {"node_id": 3}, "robot.yaml: motors.middle: unknown wheel (wheels of "
                                          "this drive: left, right)"),
        ("motors.right", ..., "robot.yaml: motors.right: driven wheel needs a motor block"),
        ("motor_defaults.driver", "tesla", "robot.yaml: motor_defaults.driver: Unknown driver "
                                           "'tesla'; expected one of: "),
        ("motor_defaults.gear_ratio", "FILL", "robot.yaml: motor_defaults.gear_ratio: expected "
                                              "float, got 'FILL'"),
        ("motors.left.gear_ratio", 0, "robot.yaml: motors.left.gear_ratio: expected at least "
                                      "0.0001, got 0.0"),
        ("motors.left.gear_ratio", 1e308, "robot.yaml: motors.left.gear_ratio: expected at most "
                                          "10000, got 1e+308"),
        ("motors.left.max_rpm", 1e6, "robot.yaml: motors.left.max_rpm: expected at most 100000, "
                                     "got 1000000.0"),
        ("geometry.wheel_radius", 1e300, "robot.yaml: geometry.wheel_radius: expected at most "
                                         "100 m, got 1e+300"),
        ("name", "", "robot.yaml: name: expected 1 to 64 printable characters, got ''"),
        ("name", "bot\u202e\x00", "robot.yaml: name: expected 1 to 64 printable characters, "
                                  "got 'bot\\u202e\\x00'"),
        ("gateway.cmd_timeout_s", 1e300, "robot.yaml: gateway.cmd_timeout_s: expected at most 60, "
                                         "got 1e+300"),
        ("motors.left.max_rpm", -5, "robot.yaml: motors.left.max_rpm: expected more than 0, got "
                                    "-5.0"),
        ("motor_defaults.max_rpm", ..., "robot.yaml: motors.left.max_rpm: required key is missing"),
        ("motors.left.colour", "red", "robot.yaml: motors.left.colour: unknown key"),
        ("motors.left.gear_ratio", math.nan, "robot.yaml: motors.left.gear_ratio: expected a "
                                             "finite number, got nan"),
        ("bus.bitrate", 3, "robot.yaml: bus.bitrate: expected at least 10000, got 3"),
        ("limits.max_linear_m_s", -1, "robot.yaml: limits.max_linear_m_s: expected at least 0"),
        ("wheels", [], "robot.yaml: wheels: only used with drive: generic"),
    ],
)
def test_bad_config_is_named_precisely(path: str, value: object, message: str) -> None:
    with pytest.raises(ConfigError) as info:
        parse_config(with_(path, value), "robot.yaml")
    assert message in str(info.value)


GENERIC_WHEEL = {"name": "a", "type": "fixed", "alpha": 1.5707963, "l": 0.2, "beta": 0.0,
                 "radius": 0.05, "motor": {"driver": "odrive", "node_id": 1, "max_rpm": 100}}


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"type": "hover"}, "robot.yaml: wheels[0].type: expected one of 'fixed', 'steerable'"),
        ({"radius": 0.0}, "robot.yaml: wheels[0].radius: expected at least 0.001 m, got 0.0"),
        ({"gamma": 0.5}, "robot.yaml: wheels[0]: wheel 'a': gamma applies to Swedish wheels"),
        ({"type": "castor"}, "robot.yaml: wheels[0]: wheel 'a': expected castor offset d > 0 m"),
        ({"type": "swedish", "gamma": 1.5707963267948966},
         "robot.yaml: wheels[0]: wheel 'a': expected |gamma| < pi/2"),
        ({"alpha": ...}, "robot.yaml: wheels[0].alpha: required key is missing"),
        ({"spin": 1}, "robot.yaml: wheels[0].spin: unknown key (known wheel keys: "),
    ],
)
def test_bad_generic_wheel(change: dict[str, object], message: str) -> None:
    wheel = {**GENERIC_WHEEL, **{k: v for k, v in change.items() if v is not ...}}
    for k, v in change.items():
        if v is ...:
            del wheel[k]
    doc = {"drive": "generic", "wheels": [wheel]}
    with pytest.raises(ConfigError) as info:
        parse_config(doc, "robot.yaml")
    assert message in str(info.value)


def test_file_errors(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"missing\.yaml: cannot read the file"):
        load_config(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("drive: [unclosed\n")
    with pytest.raises(ConfigError, match=r"bad\.yaml: not valid YAML"):
        load_config(bad)
    bad.write_text("- a list\n")
    with pytest.raises(ConfigError, match=r"bad\.yaml: expected a mapping at the top level"):
        load_config(bad)
    # A text file passed as the configuration (YAML reads it as one long string): the error
    # says what it is and quotes its start, not the whole file.
    bad.write_text("root:x:0:0:root:/root:/bin/bash\n" * 100)
    with pytest.raises(ConfigError) as err:
        load_config(bad)
    assert str(err.value).endswith(
        "got a string of 3199 characters, 'root:x:0:0:root:/root:/bin/bash root:x:0:0:root:"
        "/root:/bin/...")


def test_bus_precedence(monkeypatch: pytest.MonkeyPatch) -> None:
    doc = with_("bus", {"interface": "socketcan", "channel": "can0"})
    assert parse_config(doc, "r").bus.channel == "can0"
    monkeypatch.setenv("GATEWAY_CHANNEL", "can1")
    assert parse_config(doc, "r").bus.channel == "can1"
    assert parse_config(doc, "r", {"channel": "vcan0"}).bus.channel == "vcan0"
    monkeypatch.setenv("GATEWAY_BITRATE", "fast")
    with pytest.raises(ConfigError, match="GATEWAY_BITRATE: expected an integer bit rate"):
        parse_config(doc, "r")


@pytest.mark.parametrize(
    ("block", "message"),
    [
        ({"rate_hz": 5}, "robot.yaml: gateway.rate_hz: expected at least 50, got 5"),
        ({"rate_hz": 2000}, "robot.yaml: gateway.rate_hz: expected at most 1000, got 2000"),
        ({"infeasible_policy": "ignore"}, "robot.yaml: gateway.infeasible_policy: expected one of "
                                          "'reject', 'project', got 'ignore'"),
        ({"odom_rate_hz": 500}, "robot.yaml: gateway.odom_rate_hz: expected at most rate_hz"),
        ({"can_ids": {"twist": 0x101}}, "robot.yaml: gateway.can_ids"),
        ({"can_ids": {"status": 0x800}}, "robot.yaml: gateway.can_ids.status"),
        ({"socket_uids": ["root"]}, "robot.yaml: gateway.socket_uids: expected a list of user IDs"),
        ({"spin": 1},
         "robot.yaml: gateway.spin: unknown key; did you mean 'spin_us'? (known gateway keys: "),
    ],
)
def test_bad_gateway_block(block: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError) as info:
        parse_config({**BASE, "gateway": block}, "robot.yaml")
    assert message in str(info.value)


def test_gateway_block_defaults_and_octal_mode() -> None:
    cfg = parse_config(yaml.safe_load(yaml.safe_dump(BASE) + "gateway: {socket_mode: 0600}\n"),
                       "r")
    assert cfg.loop.socket_mode == 0o600
    assert cfg.loop.rate_hz == 200.0
    assert cfg.loop.can_ids.twist == 0x100


def test_dataclass_defaults_are_those_of_empty_blocks(monkeypatch: pytest.MonkeyPatch) -> None:
    # The key tables and the dataclasses both carry the defaults: they must agree.
    for key in ("INTERFACE", "CHANNEL", "BITRATE"):
        monkeypatch.delenv(f"GATEWAY_{key}", raising=False)
    cfg = parse_config(BASE, "r")
    assert cfg.loop == LoopConfig()
    assert cfg.bus == BusConfig()


def test_an_unknown_motor_key_suggests_the_nearest_and_lists_every_motor_key() -> None:
    raw = yaml.safe_load((REPO / "gateway" / "data" / "default.yaml").read_text())
    raw["motors"]["front_left"]["inverted"] = True
    with pytest.raises(ConfigError) as err:
        parse_config(raw, "robot.yaml")
    text = str(err.value)
    assert text.startswith("robot.yaml: motors.front_left.inverted: unknown key; did you mean "
                           "'invert'? (known motor keys: driver, gear_ratio, invert, max_rpm, "
                           "node_id; odrive keys: "), text
    raw["motors"]["front_left"] = {"node_id": 1, "colour": "red"}
    with pytest.raises(ConfigError, match=r"colour: unknown key \(known motor keys"):
        parse_config(raw, "robot.yaml")  # nothing close: no suggestion


def test_a_name_taken_from_the_file_name_is_bounded_too() -> None:
    """A file without ``name:`` takes its file name; an 80-character one was taken as it was
    (the bound applied only to a stated name)."""
    raw = yaml.safe_load(yaml.safe_dump(BASE))
    stem = "r" * 80
    with pytest.raises(ConfigError) as info:
        parse_config(raw, f"{stem}.yaml")
    assert (f"{stem}.yaml: name (the file name: state name:): expected 1 to 64 printable "
            f"characters, got '{stem}'") in str(info.value)
    assert parse_config(raw, f"{'r' * 64}.yaml").name == "r" * 64
