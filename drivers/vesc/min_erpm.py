"""The VESC's minimum ERPM: the wheel speeds its speed controller does not control.

A VESC runs its speed controller (SET_RPM) only at or above ``s_pid_min_erpm`` electrical RPM
(VESC Tool: Motor Settings > PID Controllers, Minimum ERPM; 900 from the factory,
``MCCONF_S_PID_MIN_RPM`` in ``motor/mcconf_default.h``).  In https://github.com/vedderb/bldc
(read at ``b9d287b3``):

* ``mcpwm_foc_set_pid_speed`` (``motor/mcpwm_foc.c``): a motor that is not running (released,
  timed out, never started) is started only when ``fabsf(rpm) >= s_pid_min_erpm``; below it the
  command changes nothing and the motor stays stopped (or coasts on);
* ``foc_run_pid_control_speed`` (``motor/foc_math.c``): "Too low RPM set. Reset state, release
  motor and return." -- below it the speed loop's current is zero and its integrator reset;
* the FOC interrupt (``motor/mcpwm_foc.c``): "Brake when set ERPM is below min ERPM" -- a
  running motor is held at duty 0, its phases shorted: it brakes to a stop and stays there.

The set point compared is the ramped one (``s_pid_ramp_erpms_s``, 25000 ERPM/s from the
factory), so a running motor given a small speed first follows the ramp down to
``s_pid_min_erpm`` and then brakes.  Wheel speeds whose magnitude is above zero and below that
threshold are therefore not speed-controlled: :func:`uncontrolled_band` gives them per motor,
:class:`BandWatch` counts the commands that fall in them and paces the log lines about them.

Pure: no I/O, no clock (the caller passes the time).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from drivers.vesc.codec import RPM_PER_RAD_S

if TYPE_CHECKING:
    from gateway.core.types import MotorConfig

__all__ = [
    "FACTORY_MIN_ERPM",
    "BandWatch",
    "describe_band",
    "erpm_per_wheel_rad_s",
    "in_band",
    "uncontrolled_band",
]

#: ``s_pid_min_erpm`` from the factory (``MCCONF_S_PID_MIN_RPM``, ``motor/mcconf_default.h``).
FACTORY_MIN_ERPM = 900.0
#: The counter key of commands in the band (:attr:`VescDriver.command_counts`).
BELOW_MIN_ERPM = "below_min_erpm"


def erpm_per_wheel_rad_s(pole_pairs: int, gear_ratio: float) -> float:
    """Electrical RPM per wheel rad/s (its magnitude: the sign of a motor does not matter)."""
    return abs(gear_ratio) * RPM_PER_RAD_S * pole_pairs


def uncontrolled_band(
    min_erpm: float, pole_pairs: int, gear_ratio: float
) -> tuple[float, float] | None:
    """The wheel speeds (rad/s) a VESC does not speed-control: ``(0.0, high)``, meaning every
    speed with ``0 < |speed| < high``; ``None`` when ``min_erpm`` is 0 (no band).

    >>> lo, hi = uncontrolled_band(900.0, 7, 5.0)
    >>> lo, round(hi, 3)
    (0.0, 2.693)
    """
    if min_erpm <= 0.0:
        return None
    return 0.0, min_erpm / erpm_per_wheel_rad_s(pole_pairs, gear_ratio)


def in_band(erpm: int, min_erpm: float) -> bool:
    """Whether SET_RPM ``erpm`` is not speed-controlled: nonzero and below ``min_erpm``."""
    return erpm != 0 and abs(erpm) < min_erpm


def describe_band(
    wheel: str, high_rad_s: float, min_erpm: float, wheel_radius_m: float | None = None
) -> str:
    """One line for ``wheelgate ik`` and ``check``.

    >>> describe_band("left", 2.693, 900.0, 0.1)[:51]
    "wheel 'left': |speed| below 0.27 m/s (2.69 rad/s) i"
    """
    speed = f"{high_rad_s:.3g} rad/s"
    if wheel_radius_m is not None and wheel_radius_m > 0.0:
        speed = f"{high_rad_s * wheel_radius_m:.2g} m/s ({speed})"
    return (
        f"wheel {wheel!r}: |speed| below {speed} is not speed-controlled by the VESC "
        f"(s_pid_min_erpm {min_erpm:g}): a stopped motor stays stopped, a running one brakes "
        f"to a stop"
    )


@dataclass(slots=True)
class BandWatch:
    """Paces the log lines about commands in the band: at most one per :attr:`every_s`.

    The first command in the band gets a line at once; later ones are counted, and their
    number goes with the next command in the band that comes :attr:`every_s` or more after
    the last line.
    """

    every_s: float = 5.0
    _unlogged: int = 0
    _logged_s: float | None = field(default=None)

    def note(
        self, node_id: int, wheel: str, erpm: int, min_erpm: float, now_s: float
    ) -> str | None:
        """Note one SET_RPM ``erpm`` in the band.

        :return: the line to log, or ``None`` while the last one is younger than
            :attr:`every_s`.
        """
        self._unlogged += 1
        if self._logged_s is not None and now_s - self._logged_s < self.every_s:
            return None
        more = self._unlogged - 1
        self._unlogged = 0
        self._logged_s = now_s
        return (
            f"VESC {node_id} ({wheel!r}): SET_RPM {erpm} is below min_erpm {min_erpm:g}: the "
            f"VESC does not speed-control it (s_pid_min_erpm): a stopped motor stays stopped, "
            f"a running one brakes to a stop"
            + (f" ({more} more such commands since the last line)" if more else "")
        )


def doubt(m: MotorConfig, min_erpm: float, pole_pairs: int,
          band: tuple[float, float] | None) -> str:
    """Why motor ``m``'s VESC speed-controls none of the speeds it may be commanded, or "":
    ``max_rpm`` at the wheel is inside the band below ``min_erpm`` (``band``), so the wheel can
    only stop or brake -- ``spin`` has no speed to try, a twist no speed to follow."""
    if band is None or m.steering or m.max_wheel_rad_s > band[1]:
        return ""
    return (
        f"motor {m.wheel!r}: its VESC speed-controls no speed it may be commanded: "
        f"max_rpm {m.max_rpm:g} is {m.max_wheel_rad_s:.3g} rad/s at the wheel, and "
        f"below {band[1]:.3g} rad/s (min_erpm {min_erpm:g} with pole_pairs "
        f"{pole_pairs} and gear_ratio {m.gear_ratio:g}) the VESC does not run its "
        f"speed controller; lower s_pid_min_erpm on the VESC (VESC Tool) and "
        f"min_erpm here, or check pole_pairs, gear_ratio and max_rpm")
