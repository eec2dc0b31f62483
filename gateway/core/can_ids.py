"""The arbitration IDs of wheelgate's own CAN messages: part of the validated settings
(``gateway.can_ids``), used by the wire codec (:mod:`gateway.wire.can`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.core.errors import ConfigError
from gateway.core.types import MAX_EXTENDED_ID, MAX_STANDARD_ID

if TYPE_CHECKING:
    from collections.abc import Mapping

#: The ID keys of :class:`CanIds` (and of the ``gateway.can_ids`` block), in wire order.
ID_KEYS = ("twist", "odom_pose", "odom_velocity", "status", "error")


@dataclass(frozen=True, slots=True)
class CanIds:
    """The arbitration IDs of the five messages; the defaults are the DBC's.

    :param twist: ``WG_Twist_Cmd``.
    :param odom_pose: ``WG_Odom_Pose``.
    :param odom_velocity: ``WG_Odom_Velocity``.
    :param status: ``WG_Status``.
    :param error: ``WG_Error``.
    :param extended: 29-bit identifiers instead of 11-bit ones.
    :raises ConfigError: if an ID is not an int in range for its type, or two are equal.
    """

    twist: int = 0x100
    odom_pose: int = 0x101
    odom_velocity: int = 0x102
    status: int = 0x103
    error: int = 0x104
    extended: bool = False

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Check the IDs (the constructor calls this).

        :raises ConfigError: naming the key, the expected range and the value.
        """
        if not isinstance(self.extended, bool):
            raise ConfigError(f"gateway.can_ids.extended: expected a bool, got {self.extended!r}")
        limit, kind = (MAX_EXTENDED_ID, "29-bit") if self.extended else (MAX_STANDARD_ID, "11-bit")
        seen: dict[int, str] = {}
        for name in ID_KEYS:
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= limit:
                raise ConfigError(
                    f"gateway.can_ids.{name}: expected a {kind} CAN ID between 0x0 and "
                    f"{limit:#x}, got {value!r}"
                )
            if value in seen:
                raise ConfigError(
                    f"gateway.can_ids.{name}: expected an ID no other message uses, got "
                    f"{value:#x} (also {seen[value]})"
                )
            seen[value] = name

    @classmethod
    def from_mapping(cls, block: Mapping[str, object]) -> CanIds:
        """The IDs of a ``gateway.can_ids`` block (missing keys take their defaults).

        :param block: key to value, as :attr:`gateway.core.settings.LoopConfig.can_ids` holds it.
        :raises ConfigError: for an unknown key or a bad value.
        """
        known = [*ID_KEYS, "extended"]
        for key in block:
            if key not in known:
                raise ConfigError(f"gateway.can_ids: expected keys {', '.join(known)}, got {key!r}")
        return cls(**block)  # type: ignore[arg-type]
