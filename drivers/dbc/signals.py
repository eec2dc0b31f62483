"""What one signal of a DBC file carries, and the checks :mod:`drivers.dbc.binding` makes of the
signals a motor block names.

:func:`signal_range` is the physical range of a signal (its DBC range within its bits);
:func:`checked_range` refuses a signal whose range a float cannot hold (a scale too large for its
bits); :func:`multiplexing` tells whether a signal is multiplexed; :func:`check_value` refuses a
configured value (an enable, disable or mode value) outside its signal's range or between two
of its steps, and :func:`check_enable_values` an enable and a disable value that go out as the
same raw value.  All of them run when the configuration is loaded, never per frame.
"""

from __future__ import annotations

import math
import struct
from typing import Any

from gateway.core.errors import ConfigError

#: Largest finite IEEE-754 float32.
FLOAT32_MAX = 3.4028234663852886e38


def raw_bounds(signal: Any) -> tuple[float, float]:
    """The smallest and largest raw value the bits of ``signal`` hold."""
    if signal.is_float:
        top = FLOAT32_MAX if signal.length == 32 else math.inf
        return -top, top
    if signal.is_signed:
        return -(2 ** (signal.length - 1)), 2 ** (signal.length - 1) - 1
    return 0, 2**signal.length - 1


def bits_range(signal: Any) -> tuple[float, float]:
    """The physical values of the smallest and largest raw value (in that order).

    :raises OverflowError: for a scale too large for a float (see :func:`checked_range`).
    """
    raw_lo, raw_hi = raw_bounds(signal)
    conversion = signal.conversion
    return float(conversion.raw_to_scaled(raw_lo, False)), float(
        conversion.raw_to_scaled(raw_hi, False)
    )


def signal_range(signal: Any) -> tuple[float, float]:
    """The physical range a signal can carry: its DBC range within what its bits can hold.

    :raises OverflowError: as :func:`bits_range`.
    """
    a, b = bits_range(signal)
    lo, hi = min(a, b), max(a, b)
    if signal.minimum is not None:
        lo = max(lo, float(signal.minimum))
    if signal.maximum is not None:
        hi = min(hi, float(signal.maximum))
    return lo, hi


def checked_range(
    signal: Any, shown: str, message: str, key: str, path: str, where: str
) -> tuple[float, float]:
    """:func:`signal_range`, checked: every raw value of an integer signal must have a finite
    physical value, whatever its DBC range (a float signal may carry infinities).  The codec
    relies on it: it takes the values of integer signals as finite.

    :param shown: how the message names the signal (``'Accel_Limit' (beside ...)``).
    :raises ConfigError: naming the key, the signal, its message, the DBC file, its scale,
        offset and bits.
    """
    try:
        ends = bits_range(signal)
    except OverflowError:  # cantools multiplies integer scales as ints
        ends = (math.inf, math.inf)
    if signal.is_float or all(map(math.isfinite, ends)):
        return signal_range(signal)
    raw_lo, raw_hi = raw_bounds(signal)
    raise ConfigError(
        f"{where}.{key}: expected a signal whose values a float holds, got signal {shown} of "
        f"message {message!r} in {path}: scale {signal.scale:g} and offset {signal.offset:g} "
        f"over {signal.length} bits (raw {raw_lo} to {raw_hi})"
    )


def multiplexing(message: Any, signal: Any) -> str | None:
    """How ``signal`` of ``message`` is multiplexed (for a message), else ``None``."""
    if signal.is_multiplexer:
        under = [s.name for s in message.signals if s.multiplexer_signal == signal.name]
        return f"a multiplexer switch (of {', '.join(map(repr, under)) or 'no signal'})"
    if signal.multiplexer_ids:
        ids = ", ".join(str(i) for i in signal.multiplexer_ids)
        return f"multiplexed by {signal.multiplexer_signal!r} (values {ids})"
    if message.is_container:
        return "in a container message"
    return None


def _shown(raw: float) -> str:
    return f"{raw:.9g}" if isinstance(raw, float) else str(raw)


def check_value(
    signal: Any, message: str, key: str, value: float, path: str, where: str
) -> int | float:
    """The raw value ``value`` goes out as in ``signal``.

    The value must be in the signal's range and on one of its steps: an integer signal rounds
    to the nearest step, so a value between two would go out as another one (within a millionth
    of a step is on it: a decimal scale is not exact in binary); a float32 signal rounds to its
    precision.

    :raises ConfigError: naming the key, the signal, its message and the DBC file, the range or
        the step, and what the value would go out as.
    """
    lo, hi = signal_range(signal)
    if not lo <= value <= hi:
        raise ConfigError(
            f"{where}.{key}: expected a value between {lo:g} and {hi:g} for signal "
            f"{signal.name!r} of message {message!r} in {path}, got {value!r}"
        )
    raw = signal.conversion.numeric_scaled_to_raw(value)
    if signal.is_float:
        if signal.length == 32:
            raw = struct.unpack("<f", struct.pack("<f", raw))[0]
        back = float(signal.conversion.raw_to_scaled(raw, False))
        ok = math.isclose(back, value, rel_tol=1e-6 if signal.length == 32 else 1e-12)
    else:
        back = float(signal.conversion.raw_to_scaled(raw, False))
        exact = (value - float(signal.offset)) / float(signal.scale)
        ok = math.isclose(exact, raw, rel_tol=1e-12, abs_tol=1e-6)
    if not ok:
        raise ConfigError(
            f"{where}.{key}: expected a value on a step of signal {signal.name!r} of message "
            f"{message!r} in {path} (scale {signal.scale:g}, offset {signal.offset:g}), got "
            f"{value!r}, which goes out as {back:g} (raw {_shown(raw)})"
        )
    return raw  # type: ignore[no-any-return]


def check_enable_values(
    signal: Any, message: str, values: tuple[float, float], path: str, where: str
) -> None:
    """Check the enable and disable values (``values``) of an enable signal: each with
    :func:`check_value`, and that they go out as different raw values.

    :raises ConfigError: as :func:`check_value`, or naming both values and their raw value.
    """
    armed, disarmed = (
        check_value(signal, message, key, value, path, where)
        for key, value in zip(("enable_value", "disable_value"), values, strict=True)
    )
    if armed == disarmed:
        raise ConfigError(
            f"{where}.disable_value: expected a value that goes out other than enable_value "
            f"{values[0]!r} (raw {_shown(armed)}) in signal {signal.name!r} of message "
            f"{message!r} in {path}, got {values[1]!r}, which goes out as raw "
            f"{_shown(disarmed)} too"
        )
