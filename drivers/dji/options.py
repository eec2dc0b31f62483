"""Protocol keys of a ``driver: dji`` motor block, declared once as :class:`DjiOptions`.

The keys and their meaning follow the RoboMaster C620/C610 user guides (ESC types and full-scale
currents) and the host-side loops of :mod:`drivers.dji.pi` and :mod:`drivers.dji.position`:

* ``esc``: ``"c620"`` (M3508, the default) or ``"c610"`` (M2006);
* ``kp``: A per rad/s of **rotor** speed error (0.1); ``ki``: A per rad of integrated rotor speed
  error (1.0); ``max_current_a``: the current limit, 0 for the ESC's full scale (20 A C620,
  10 A C610; more is refused);
* ``liveness_s``: feedback older than this is OFFLINE (0.1 s here, one value for every motor of
  the bus); ``max_temp_c``: the host-side over-temperature limit of a C620 (80 degC);
* ``no_controller_stop: acknowledged``, required (:mod:`drivers.dji.protection`);
* steering actuators only (an error in a drive motor's block, checked by the driver, which knows
  the motor's role): ``steer_kp`` (35 1/s) and ``steer_kd`` (0.7)
  (:data:`drivers.dji.position.STEERING_OPTIONS`).  A block that does not give them keeps
  them out of its validated keys, so a drive motor's block never shows them.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

from drivers.dji.codec import ESC_MODELS, EscModel
from drivers.dji.position import STEERING_OPTIONS
from drivers.dji.protection import ACK_OPTION, check_acknowledged
from gateway.core.errors import ConfigError
from gateway.drive.options import DriverOptions, option, spec_field

if TYPE_CHECKING:
    from collections.abc import Mapping

__all__ = ["DEFAULT_LIVENESS_S", "DjiOptions"]

#: The ESCs send feedback at 1 kHz: 0.1 s of silence is a hundred frames lost.
DEFAULT_LIVENESS_S = 0.1


@dataclass(frozen=True, kw_only=True)
class DjiOptions(DriverOptions):
    """The validated protocol keys of one DJI motor block (see the module docstring).

    :param esc: the ESC type, a key of :data:`drivers.dji.codec.ESC_MODELS`.
    :param kp: proportional gain of the speed loop, A per rad/s of rotor speed error.
    :param ki: integral gain, A per rad of integrated rotor speed error.
    :param max_current_a: current limit (A), 0 for the ESC's full scale.
    :param max_temp_c: C620 over-temperature limit (degC).
    :param no_controller_stop: must be ``"acknowledged"``.
    :param steer_kp: steering actuators: position gain (1/s).
    :param steer_kd: steering actuators: damping.
    """

    liveness_s: float = spec_field(
        dataclasses.replace(
            DriverOptions.specs()["liveness_s"],
            default=DEFAULT_LIVENESS_S,
            help="feedback older than this is OFFLINE (s)",
        )
    )
    esc: str = option(
        str, "c620", choices=tuple(ESC_MODELS), help="ESC type: c620 (M3508), c610 (M2006)"
    )
    kp: float = option(
        float, 0.1, minimum=0.0, help="proportional gain, A per rad/s of rotor speed error"
    )
    ki: float = option(
        float, 1.0, minimum=0.0, help="integral gain, A per rad of integrated rotor error"
    )
    max_current_a: float = option(
        float, 0.0, minimum=0.0, maximum=20.0, help="current limit in A, 0 = full scale"
    )
    max_temp_c: float = option(
        float, 80.0, minimum=0.0, maximum=255.0, help="C620 over-temperature limit (degC)"
    )
    no_controller_stop: str = spec_field(ACK_OPTION)
    steer_kp: float = spec_field(STEERING_OPTIONS["steer_kp"])
    steer_kd: float = spec_field(STEERING_OPTIONS["steer_kd"])

    @classmethod
    def validate(cls, raw: Mapping[str, object], where: str) -> dict[str, object]:
        """The keys of a motor block, checked and completed with defaults, except the
        steering keys, which stay out unless given.

        :raises ConfigError: for an unknown key, a bad value, a block without
            ``no_controller_stop: acknowledged``
            (:func:`drivers.dji.protection.check_acknowledged`), or a ``max_current_a`` above
            the ESC's full scale.
        """
        out = super().validate(raw, where)
        check_acknowledged(out, where)
        esc = ESC_MODELS[str(out["esc"])]
        limit = out["max_current_a"]
        if isinstance(limit, float) and limit > esc.full_scale_a:
            raise ConfigError(
                f"{where}.max_current_a: expected at most {esc.full_scale_a:g} A for a "
                f"{esc.name.upper()}, got {limit:g}"
            )
        for key in STEERING_OPTIONS:
            if key not in raw:
                del out[key]
        return out

    @property
    def model(self) -> EscModel:
        """The ESC type."""
        return ESC_MODELS[self.esc]

    @property
    def current_limit_a(self) -> float:
        """The speed loop's current limit (A): ``max_current_a``, or the ESC's full scale."""
        return self.max_current_a or self.model.full_scale_a
