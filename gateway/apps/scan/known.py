"""The configuration's motors (``scan -c``) matched with the controllers a scan found.

A controller is a motor block's when the driver, the node ID **and the identifier type** agree:
an ODrive axis answering on 29-bit identifiers (``axis.config.can.is_extended``) is not the
block of the same node on 11-bit ones, whose driver would send it frames it never takes, so
that motor would never enable.  The identifier types of a block are those of the frames its
driver declares as that motor's (:class:`~gateway.apps.scan.own.MotorClaims`); a motor whose
frames are not known (no claims given) is matched by driver and node ID alone.  A controller
that differs from a block only in its identifiers is said so on its row, and the block is
named as not found, with what differs.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.core.errors import DriverNotFoundError
from gateway.drive.registry import get_driver_class

if TYPE_CHECKING:
    from collections.abc import Iterable, Sequence

    from gateway.apps.scan.own import MotorClaims
    from gateway.core.options import OptionSpec
    from gateway.core.types import MotorConfig

#: The motor-block key that chooses the identifier type, for the drivers that have one.
EXTENDED_KEY = "extended_id"


def bits(extended: bool) -> str:
    """``"29-bit"`` or ``"11-bit"``."""
    return "29-bit" if extended else "11-bit"


@dataclass(frozen=True, slots=True)
class KnownMotor:
    """A motor block of the configuration.

    :param motor: the block.
    :param extended: the identifier types of its declared frames (empty: not known).
    """

    motor: MotorConfig
    extended: frozenset[bool]

    def takes(self, extended: bool) -> bool:
        """Whether a controller on these identifiers can be this block's."""
        return not self.extended or extended in self.extended

    def label(self, identifiers: bool = True, more: str = "") -> str:
        """``'left' (odrive node 1 on 11-bit identifiers)`` (without ``identifiers``, or when
        they are not known or of both types: ``'left' (odrive node 1)``), ``more`` added in
        the brackets."""
        m = self.motor
        on = (f" on {bits(next(iter(self.extended)))} identifiers"
              if identifiers and len(self.extended) == 1 else "")
        return f"{m.wheel!r} ({m.driver} node {m.node_id}{on}{more})"


class KnownMotors:
    """The configuration's motors, by driver and node ID (see the module)."""

    def __init__(self, motors: Sequence[MotorConfig] = (),
                 claimed: Sequence[MotorClaims] = ()) -> None:
        types: dict[tuple[str, int], frozenset[bool]] = {}
        for c in claimed:
            key = (c.motor.driver, c.motor.node_id)
            types[key] = types.get(key, frozenset()) | {claim.extended for claim in c.claims}
        self.motors = tuple(KnownMotor(m, types.get((m.driver, m.node_id), frozenset()))
                            for m in motors)
        self._by_node = {(k.motor.driver, k.motor.node_id): k for k in self.motors}

    def _block(self, driver: str | None, node_id: int | None) -> KnownMotor | None:
        if driver is None or node_id is None:
            return None
        return self._by_node.get((driver, node_id))

    def wheel(self, driver: str | None, node_id: int | None, extended: bool) -> str | None:
        """The wheel of the block this controller is, if any."""
        k = self._block(driver, node_id)
        return k.motor.wheel if k is not None and k.takes(extended) else None

    def differs(self, driver: str | None, node_id: int | None, extended: bool) -> str | None:
        """What makes this controller not the block of its driver and node ID, when only its
        identifiers do; ``None`` otherwise."""
        k = self._block(driver, node_id)
        if k is None or k.takes(extended):
            return None
        fix = ""
        if extended_spec(k.motor.driver) is not None:
            fix = f" (set {EXTENDED_KEY}: {'true' if extended else 'false'} in that block)"
        return (f"not the configuration's {k.label()}: this controller answers on "
                f"{bits(extended)} identifiers{fix}")

    def missing(self, found: Iterable[tuple[str | None, int | None, bool]]
                ) -> list[tuple[MotorConfig, str]]:
        """Every block no controller found (``(driver, node ID, extended)``) is, with its
        words, ``'left' (odrive node 1)`` (and the identifiers its node was heard on instead,
        if it was: ``'left' (odrive node 1 on 11-bit identifiers; heard on 29-bit identifiers
        instead)``)."""
        found = list(found)
        matched = {self.wheel(*f) for f in found}
        out = []
        for k in self.motors:
            if k.motor.wheel in matched:
                continue
            other = sorted({bits(e) for d, n, e in found
                            if (d, n) == (k.motor.driver, k.motor.node_id) and not k.takes(e)})
            heard = f"; heard on {' and '.join(other)} identifiers instead" if other else ""
            out.append((k.motor, k.label(bool(other), heard)))
        return out


def extended_spec(driver: str) -> OptionSpec | None:
    """The driver's :data:`EXTENDED_KEY` option, when its blocks choose the identifier type
    (``None``: they do not, or no such driver: the loader says why)."""
    try:
        return get_driver_class(driver).OPTIONS.get(EXTENDED_KEY)
    except DriverNotFoundError:
        return None
