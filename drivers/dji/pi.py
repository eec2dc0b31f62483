"""Host-side rotor-speed PI controller for current-only ESCs (pure; no clock, no state).

DJI C620 / C610 ESCs take only a torque-current set point over CAN, so the gateway closes the
speed loop itself, as DJI's example firmware does on the MCU
(`Development-Board-C-Examples <https://github.com/RoboMaster/Development-Board-C-Examples>`_,
``chassis_task.c``).  The controller works in the **motor (rotor) frame**: the error is in rad/s
of rotor speed, the output in A of torque current.

.. math::

    e = \\omega_{target} - \\omega_{measured}, \\qquad
    I_{k} = \\operatorname{clip}(I_{k-1} + k_i e \\, \\Delta t, -i_{max}, i_{max}), \\qquad
    i = \\operatorname{clip}(k_p e + I_k, -i_{max}, i_{max})

Anti-windup is conditional integration: while the output saturates and the error would drive
it further into saturation, the integrator holds its value.  The integrator state is kept in A
(the integral term's contribution), so it is bounded by the current limit and gain changes do
not bump the output.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class SpeedPi:
    """Gains and limit of one motor's speed loop.

    :param kp_a_per_rad_s: proportional gain, A of current per rad/s of rotor speed error.
    :param ki_a_per_rad: integral gain, A per rad of integrated rotor speed error
        (A per rad/s per s).
    :param limit_a: output and integrator limit in A (> 0).
    """

    kp_a_per_rad_s: float
    ki_a_per_rad: float
    limit_a: float

    def step(self, integral_a: float, error_rad_s: float, dt_s: float) -> tuple[float, float]:
        """One controller update (every motor, every cycle: the clipping is written out).

        :param integral_a: integrator state from the previous update (A).
        :param error_rad_s: target minus measured rotor speed (rad/s).
        :param dt_s: time since the previous update (s, >= 0; a negative value counts as 0).
        :return: ``(current_a, new_integral_a)``; the current is within the limit.
        """
        if not math.isfinite(error_rad_s):
            return 0.0, 0.0
        lim = self.limit_a
        p = self.kp_a_per_rad_s * error_rad_s
        integral = integral_a + self.ki_a_per_rad * error_rad_s * dt_s if dt_s > 0.0 else integral_a
        if integral > lim:
            integral = lim
        elif integral < -lim:
            integral = -lim
        out = p + integral
        if (out > lim and error_rad_s > 0.0) or (out < -lim and error_rad_s < 0.0):
            # Saturated and the error pushes further: hold the integrator.
            integral = lim if integral_a > lim else -lim if integral_a < -lim else integral_a
            out = p + integral
        if out > lim:
            return lim, integral
        if out < -lim:
            return -lim, integral
        return out, integral
