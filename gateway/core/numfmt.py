"""Numbers for people: rounded to the quantity's resolution, never a negative zero.

Floating-point arithmetic leaves noise where a person expects a round number: a lateral speed
of ``-2.776e-17`` m/s from a least-squares solve, ``-0.00`` for a wheel at rest that turns
backwards by a hair.  Every human output (the CLI's text, the ``jog`` and ``monitor`` screens,
messages) writes its numbers through these functions, each at the resolution of its quantity
(``places`` decimals); JSON and CSV keep the full precision of the value.

>>> fixed(-2.7755575615628914e-17, 3, sign=True)
'+0.000'
>>> fixed(-0.0004, 2)
'0.00'
>>> short(-2.7755575615628914e-17, 4), short(0.30000000000000004, 4), short(-12.5, 4)
('0', '0.3', '-12.5')
"""

from __future__ import annotations

__all__ = ["fixed", "rounded", "short"]


def rounded(value: float, places: int) -> float:
    """``value`` rounded to ``places`` decimals, a value that rounds to zero as ``0.0`` (never
    ``-0.0``); NaN and infinities are returned as they are."""
    out = round(value, places)
    return 0.0 if out == 0.0 else out


def fixed(value: float, places: int, *, sign: bool = False) -> str:
    """``value`` with exactly ``places`` decimals (``f"{value:.3f}"``), without the minus sign
    of a value that rounds to zero.

    :param value: the number.
    :param places: decimals shown, the quantity's resolution (3 for m/s: 1 mm/s).
    :param sign: write ``+`` before a positive number and zero, as ``f"{value:+.3f}"``.
    """
    return f"{rounded(value, places):{'+' if sign else ''}.{places}f}"


def short(value: float, places: int, *, sign: bool = False) -> str:
    """``value`` rounded to ``places`` decimals with the trailing zeros dropped (``0.5``,
    ``0``, ``-0.125``): as short as ``f"{value:g}"`` but never in exponent notation and never
    ``-0``.

    :param value: the number.
    :param places: the finest decimal written, the quantity's resolution.
    :param sign: write ``+`` before a positive number and zero (``+0.5``, ``+0``).
    """
    text = fixed(value, places, sign=sign)
    if "." in text:
        text = text.rstrip("0").rstrip(".")
    return text
