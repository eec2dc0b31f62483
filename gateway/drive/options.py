"""A driver's protocol keys, declared once as a frozen dataclass.

Each driver declares the keys of its motor blocks as the fields of a :class:`DriverOptions`
subclass, each field made with :func:`option` (its :class:`~gateway.core.options.OptionSpec`:
type, default, bounds, choices, one line of help).  The same declaration gives

* the configuration's validation and defaults (:meth:`DriverOptions.specs` and
  :meth:`DriverOptions.from_block`, one :class:`~gateway.core.errors.ConfigError` naming the key,
  what was expected and what came);
* the driver its typed, validated options (``driver.opts[i].liveness_s``), no string lookups;
* ``wheelgate check`` and the docs their list of keys.

The keys every protocol has are declared once, here: ``liveness_s`` (every driver) and
``controller_timeout_s`` (:class:`StatedTimeout`, for the protocols whose controllers' command
timeout is set with the vendor's tool and stated in the configuration).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar, cast

from gateway.core.errors import ConfigError
from gateway.core.options import OptionSpec, validate_block

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from gateway.core.types import MotorConfig

__all__ = [
    "CONTROLLER_TIMEOUT_OPTION",
    "DEFAULT_LIVENESS_S",
    "DriverOptions",
    "StatedTimeout",
    "check_bus_wide",
    "option",
]

OptT = TypeVar("OptT", bound="DriverOptions")

#: Feedback older than this marks a motor OFFLINE (s), unless a driver declares otherwise.
DEFAULT_LIVENESS_S = 0.25

#: The common ``controller_timeout_s`` key of protocols that cannot set their controller's
#: timeout over CAN: the timeout that was set with the vendor's tool, as a statement.
CONTROLLER_TIMEOUT_OPTION = OptionSpec(
    float,
    0.0,
    minimum=0.0,
    maximum=60.0,
    help="the command timeout set on the controller with the vendor's tool (s), after which "
    "it stops the motor by itself; 0: not stated",
)

_SPEC = "wheelgate.option"


def option(
    kind: type,
    default: object = None,
    *,
    choices: tuple[object, ...] = (),
    minimum: float | None = None,
    maximum: float | None = None,
    help: str = "",  # noqa: A002 - the OptionSpec field's name
    above: float | None = None,
) -> Any:
    """A dataclass field that is a protocol key (``default=None``: the key is required;
    ``above``: a number it must exceed, as a ratio that must not be 0)."""
    return spec_field(OptionSpec(kind, default, choices, minimum, maximum, help, above))


def spec_field(spec: OptionSpec) -> Any:
    """A dataclass field for an existing :class:`OptionSpec` (a key shared by protocols)."""
    meta = {_SPEC: spec}
    if spec.default is None:
        return dataclasses.field(metadata=meta)
    if isinstance(spec.default, (dict, list, set)):
        frozen = spec.default
        return dataclasses.field(default_factory=lambda: type(frozen)(frozen), metadata=meta)
    return dataclasses.field(default=spec.default, metadata=meta)


@dataclass(frozen=True, kw_only=True)
class DriverOptions:
    """The validated protocol keys of one motor block (subclass per driver).

    :param liveness_s: feedback older than this (s) marks the motor OFFLINE.
    """

    liveness_s: float = option(
        float,
        DEFAULT_LIVENESS_S,
        minimum=0.001,
        help="seconds without feedback before a motor is OFFLINE",
    )

    @classmethod
    def specs(cls) -> dict[str, OptionSpec]:
        """Every key of this block, by name, in declaration order."""
        return {
            f.name: f.metadata[_SPEC] for f in dataclasses.fields(cls) if _SPEC in f.metadata
        }

    @classmethod
    def validate(cls, raw: Mapping[str, object], where: str) -> dict[str, object]:
        """The keys of a motor block, checked and completed with defaults (the form a
        :class:`~gateway.core.types.MotorConfig` keeps).

        :raises ConfigError: for an unknown key, a missing required key or a bad value.
        """
        return validate_block(raw, cls.specs(), where, "protocol keys for this driver")

    @classmethod
    def from_block(cls: type[OptT], raw: Mapping[str, object], where: str) -> OptT:
        """The options of a motor block.

        :raises ConfigError: as :meth:`validate`.
        """
        return cls(**cast("dict[str, Any]", cls.validate(raw, where)))


@dataclass(frozen=True, kw_only=True)
class StatedTimeout(DriverOptions):
    """The options of a protocol whose controllers' command timeout is stated, not set over CAN.

    :param controller_timeout_s: the timeout set with the vendor's tool (s); 0: not stated.
    """

    controller_timeout_s: float = spec_field(CONTROLLER_TIMEOUT_OPTION)


def check_bus_wide(
    motors: Sequence[MotorConfig], opts: Sequence[DriverOptions], keys: Sequence[str],
    protocol: str,
) -> None:
    """Check that every motor of one bus agrees on ``keys`` (a driver's ``BUS_WIDE``).

    :raises ConfigError: naming the first motor that differs from the first one, and the key.
    """
    for m, o in zip(motors, opts, strict=True):
        for key in keys:
            want, got = getattr(opts[0], key), getattr(o, key)
            if got != want:
                raise ConfigError(
                    f"motor {m.wheel!r}.{key}: expected {want!r} like motor "
                    f"{motors[0].wheel!r} on the same {protocol} bus, got {got!r}"
                )
