"""The strict YAML reading on libyaml's parser and on PyYAML's pure-Python one: the same data,
the same refusals, and PyYAML's fuller syntax-error messages either way."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from gateway.config import yaml_text
from gateway.config.yaml_text import MAX_DEPTH, MAX_NUMBER, MAX_SCALAR, load_yaml
from gateway.core.errors import ConfigError
from tests.conftest import CONFIG_DIR

DEFAULT = Path(yaml_text.__file__).parents[1] / "data" / "default.yaml"
LOADERS = [yaml_text._PyLoader, yaml_text._Loader]

needs_libyaml = pytest.mark.skipif(
    not yaml.__with_libyaml__, reason="PyYAML built without libyaml: only the Python loader"
)


def parse(cls: type[yaml_text._Strict], text: str) -> object:
    return yaml_text._parse(cls, text, "robot.yaml")


@needs_libyaml
def test_libyaml_parses_when_pyyaml_has_it() -> None:
    assert yaml_text._Loader is not yaml_text._PyLoader
    assert yaml_text._Loader.__name__ == "_CLoader"


@pytest.mark.parametrize("path", [DEFAULT, *sorted(CONFIG_DIR.glob("*.yaml"))],
                         ids=lambda p: p.name)
def test_both_loaders_read_every_shipped_configuration_alike(path: Path) -> None:
    text = path.read_text()
    assert parse(yaml_text._Loader, text) == parse(yaml_text._PyLoader, text) \
        == yaml.safe_load(text)


#: Case -> (text, the message after "robot.yaml: line <n>: ").
BAD = {
    "key twice": ("a: 1\nb: 2\na: 3\n", "key 'a' is given twice in one mapping (first on line 1)"),
    "anchor": ("a: &x 1\nb: *x\n", "expected plain YAML, got the anchor &x"),
    "alias": ("b: *x\n", "expected plain YAML, got the alias *x"),
    "long scalar": (f"a: {'x' * (MAX_SCALAR + 1)}\n",
                    f"expected a value of at most {MAX_SCALAR} characters"),
    "long number": (f"a: {'1' * (MAX_NUMBER + 1)}\n",
                    f"expected a number of at most {MAX_NUMBER} characters"),
    "deep": ("a: " + "[" * (MAX_DEPTH + 1) + "]" * (MAX_DEPTH + 1) + "\n",
             f"expected at most {MAX_DEPTH} levels of nesting"),
    "key not plain": ("? [1, 2]\n: 3\n", "expected a plain key, got a sequence"),
}


@pytest.mark.parametrize("loader", LOADERS, ids=lambda c: c.__name__)
@pytest.mark.parametrize("case", sorted(BAD))
def test_both_loaders_refuse_alike(loader: type[yaml_text._Strict], case: str) -> None:
    text, expected = BAD[case]
    with pytest.raises(ConfigError) as err:
        load_yaml(text, "robot.yaml") if loader is yaml_text._Loader else parse(loader, text)
    assert re.match(r"robot\.yaml: line \d+: ", str(err.value)), str(err.value)
    assert expected in str(err.value)


def test_a_syntax_error_names_the_file_and_line_and_shows_it() -> None:
    with pytest.raises(ConfigError) as err:
        load_yaml("wheels:\n  - name: a\n    radius_m: [0.1, 0.2\n  - name: b\n", "robot.yaml")
    text = str(err.value)
    assert text.startswith("robot.yaml: not valid YAML: while parsing a flow sequence")
    assert 'line 3, column 15:\n        radius_m: [0.1, 0.2\n                  ^' in text, text


@pytest.mark.parametrize("loader", LOADERS, ids=lambda c: c.__name__)
def test_a_number_with_an_exponent_is_a_number_as_in_yaml_1_2(
    loader: type[yaml_text._Strict],
) -> None:
    # YAML 1.1 (PyYAML's rules) reads 1e-3 and 1.5e3 as text, and a motor block's
    # `max_rpm: 3e3` would be refused as "expected float, got '3e3'".
    got = parse(loader, "a: 1e-3\nb: 1.5e3\nc: -2E+2\nd: .5e1\ne: 12\nf: e3\ng: 1e\nh: v1e3\n")
    assert got == {"a": 0.001, "b": 1500.0, "c": -200.0, "d": 5.0, "e": 12, "f": "e3",
                   "g": "1e", "h": "v1e3"}
    assert isinstance(got, dict) and type(got["e"]) is int
