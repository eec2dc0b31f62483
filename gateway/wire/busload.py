"""Bits on the wire per classical CAN frame, for bus-load figures.

Frame length including the 3-bit intermission; worst-case bit stuffing after Davis, Burns,
Bril and Lukkien (2007): ``g + 8n + 13 + floor((g + 8n - 1) / 4)`` with ``g = 34`` (standard)
or ``54`` (extended).  Nominal is without stuff bits.

>>> frame_bits(8, extended=False), frame_bits(8, extended=False, worst_case=True)
(111, 135)
>>> frame_bits(0, extended=True), frame_bits(0, extended=True, worst_case=True)
(67, 80)
"""

from __future__ import annotations


def frame_bits(dlc: int, extended: bool, worst_case: bool = False) -> int:
    """Bits one frame occupies on the bus (a remote frame counts with ``dlc = 0``)."""
    g = 54 if extended else 34
    n = min(max(dlc, 0), 8)
    nominal = g + 8 * n + 13
    return nominal + (g + 8 * n - 1) // 4 if worst_case else nominal


def bus_load(bits_per_s: float, bitrate: int) -> float:
    """Bus load in percent of ``bitrate``."""
    return 100.0 * bits_per_s / bitrate if bitrate > 0 else 0.0
