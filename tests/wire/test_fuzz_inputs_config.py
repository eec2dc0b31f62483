"""Fuzzing of the gateway's configuration input.

Random YAML-able documents, mutations of every shipped configuration (keys deleted, types
changed, keys added, NaN / infinity / huge values), random bytes in a file, random bus
overrides: ``parse_config`` / ``load_config`` raise ``ConfigError`` only.
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest
import yaml
from hypothesis import example, given, settings
from hypothesis import strategies as st

from gateway.config import load_config, parse_config
from gateway.core.errors import ConfigError
from tests.conftest import CONFIG_DIR
from tests.wire.fuzz_input_helpers import FUZZ

if TYPE_CHECKING:
    from collections.abc import Iterator


# =============================================================================== configuration

SHIPPED = sorted(CONFIG_DIR.glob("*.yaml"))
KEYS = sorted({
    "name", "drive", "geometry", "wheels", "motors", "motor_defaults", "limits", "kinematics",
    "bus", "gateway", "wheel_radius", "track", "wheelbase", "driver", "node_id", "gear_ratio",
    "max_rpm", "invert", "firmware", "extended_id", "pole_pairs", "esc", "dbc", "interface",
    "channel", "bitrate", "rate_hz", "can_ids", "twist", "type", "alpha", "l", "beta",
    "radius", "motor", "left", "right", "max_steer", "wheel_count", "wheel_distance",
})
DRIVES = ["differential", "skid_steer", "synchro", "tricycle", "ackermann", "omni", "mecanum",
          "swerve", "generic"]
scalars = (
    st.none()
    | st.booleans()
    | st.integers(-(10**30), 10**30)
    | st.sampled_from([0, 1, 2, 3, 63, 0x7FF, 2**31, 2**64, -1])
    | st.floats()
    | st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, 5e-324, 1e-9, -0.0])
    | st.text(max_size=12)
    | st.sampled_from([*DRIVES, "odrive", "vesc", "dji", "cia402", "dbc", "0.6", "c620", ""])
)
yaml_docs = st.recursive(
    scalars,
    lambda children: st.lists(children, max_size=4)
    | st.dictionaries(st.sampled_from(KEYS) | st.text(max_size=6) | st.integers(), children,
                      max_size=6),
    max_leaves=25,
)


def parse_or_config_error(doc: object, source: str) -> None:
    try:
        cfg = parse_config(doc, source)
    except ConfigError as err:
        assert str(err)
    else:
        assert cfg.model.wheels


@FUZZ
@given(doc=yaml_docs | st.fixed_dictionaries(
    {"drive": st.sampled_from(DRIVES)},
    optional=dict.fromkeys(("geometry", "motors", "motor_defaults", "wheels", "limits", "bus",
                            "gateway", "kinematics", "name"), yaml_docs),
))
def test_random_documents_raise_only_config_error(doc: object) -> None:
    parse_or_config_error(doc, "fuzz.yaml")


def _paths(doc: object, prefix: tuple[Any, ...] = ()) -> Iterator[tuple[Any, ...]]:
    if prefix:
        yield prefix
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from _paths(v, (*prefix, i))


def _mutate(doc: Any, draw: st.DrawFn) -> None:
    """One mutation at a random place (a leaf, mostly): delete the key, replace the value
    (mostly by a scalar of another type), add a key, or wrap the value in a list."""
    paths = list(_paths(doc))
    leaves = [p for p in paths if not isinstance(_get(doc, p), (dict, list))]
    pool = leaves if leaves and draw(st.integers(0, 9)) < 7 else paths
    path = draw(st.randoms(use_true_random=False)).choice(pool)  # uniform, unlike sampled_from
    parent, key = _get(doc, path[:-1]), path[-1]
    op = draw(st.sampled_from(["delete", "replace", "replace", "replace", "add", "wrap"]))
    if op == "delete" and isinstance(parent, dict):
        del parent[key]
    elif op == "add" and isinstance(parent, dict):
        parent[draw(st.sampled_from(KEYS) | st.text(max_size=4))] = draw(yaml_docs)
    elif op == "wrap":
        parent[key] = [parent[key]]
    else:
        parent[key] = draw(st.one_of(scalars, scalars, yaml_docs))


def _get(doc: Any, path: tuple[Any, ...]) -> Any:
    for key in path:
        doc = doc[key]
    return doc


@st.composite
def mutated_configs(draw: st.DrawFn) -> tuple[Any, str]:
    path = draw(st.sampled_from(SHIPPED))
    doc = yaml.safe_load(path.read_text("utf-8"))
    for _ in range(draw(st.integers(1, 4))):
        _mutate(doc, draw)
    return doc, str(path)


@settings(FUZZ, max_examples=300)
@given(case=mutated_configs())
def test_mutated_shipped_configs_raise_only_config_error(case: tuple[Any, str]) -> None:
    doc, source = case
    parse_or_config_error(doc, source)


def test_every_shipped_config_loads() -> None:
    """The mutation test starts from valid files."""
    for path in SHIPPED:
        assert load_config(path).model.wheels


@contextlib.contextmanager
def _written(data: bytes) -> Iterator[str]:
    """A private file holding ``data``."""
    folder = tempfile.mkdtemp(prefix="wgfz")
    try:
        path = os.path.join(folder, "robot.yaml")
        Path(path).write_bytes(data)
        yield path
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def load_or_config_error(data: bytes) -> None:
    with _written(data) as path:
        try:
            load_config(path)
        except ConfigError as err:
            assert str(err).startswith(path)


yaml_text = st.text(
    st.characters(codec="utf-8") | st.sampled_from(list(":-[]{},#&*!|>'\"%@ \n\t")),
    max_size=200,
)


@FUZZ
@given(text=yaml_text | st.builds(yaml.safe_dump, yaml_docs))
def test_load_config_on_random_text_raises_only_config_error(text: str) -> None:
    load_or_config_error(text.encode("utf-8"))


@FUZZ
@example(data=b"\xff\xfedrive: differential\n")
@given(data=st.binary(max_size=200))
def test_load_config_on_random_bytes_raises_only_config_error(data: bytes) -> None:
    load_or_config_error(data)


def test_load_config_on_deeply_nested_yaml_raises_config_error() -> None:
    load_or_config_error(b"drive: " + b"[" * 2000 + b"]" * 2000 + b"\n")


def test_a_huge_wheel_count_is_refused_as_such() -> None:
    doc = yaml.safe_load((CONFIG_DIR / "omni3.yaml").read_text("utf-8"))
    doc["geometry"]["wheel_count"] = 10**12  # refused before any wheel is built
    with pytest.raises(ConfigError) as err:
        parse_config(doc, str(CONFIG_DIR / "omni3.yaml"))
    assert "wheel_count" in str(err.value), str(err.value)


bus_values = scalars | st.text(max_size=30)


@FUZZ
@given(interface=bus_values, channel=bus_values, bitrate=bus_values, env=st.none() | st.text())
def test_bus_overrides_raise_only_config_error(
    interface: object, channel: object, bitrate: object, env: str | None
) -> None:
    old = os.environ.pop("GATEWAY_BITRATE", None)
    if env is not None and "\x00" not in env:
        os.environ["GATEWAY_BITRATE"] = env
    try:
        load_config(None, {"interface": interface, "channel": channel, "bitrate": bitrate})
    except ConfigError as err:
        assert str(err)
    finally:
        os.environ.pop("GATEWAY_BITRATE", None)
        if old is not None:
            os.environ["GATEWAY_BITRATE"] = old
