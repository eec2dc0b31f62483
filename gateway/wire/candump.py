"""The candump log format (``candump -l``, python-can's ``.log``), read line by line.

A line is ``(1700000000.123456) can0 06D#0000204100000000 T``: a timestamp in seconds, the
interface, the frame in ``cansend`` syntax (3 hex digits for a standard ID, 8 for an extended
one, ``R`` for a remote frame) and, as python-can writes it, ``R``/``T`` for received or
transmitted.  This reader is pure and strict: a line it cannot read raises
:class:`CandumpError` with the line number, so callers can report it and go on.

>>> entry = parse_line("(12.5) can0 06D#0000204100000000 T", 1)
>>> entry.timestamp_s, entry.channel, entry.is_rx, entry.frame.to_cansend()
(12.5, 'can0', False, '06D#0000204100000000')
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.core.errors import DecodeError
from gateway.core.types import Frame

if TYPE_CHECKING:
    from collections.abc import Iterable, Iterator


_HEX = frozenset("0123456789abcdefABCDEF")


class CandumpError(DecodeError):
    """A line of a candump log that cannot be read.

    :param line_number: 1-based line number.
    """

    def __init__(self, message: str, line_number: int) -> None:
        super().__init__(f"line {line_number}: {message}")
        self.line_number = line_number


@dataclass(frozen=True, slots=True)
class LogEntry:
    """One frame of a log.

    :param timestamp_s: the recorded time, s.
    :param channel: the interface name.
    :param frame: the frame (its ``timestamp_s`` is the recorded time).
    :param is_rx: received (``R``, or no direction token) rather than transmitted (``T``).
    """

    timestamp_s: float
    channel: str
    frame: Frame
    is_rx: bool


#: CAN_ERR_FLAG of SocketCAN, which candump and python-can write into an error frame's ID.
CAN_ERR_FLAG = 0x20000000


def is_error_frame_line(line: str) -> bool:
    """Whether a candump line carries an error frame (CAN_ERR_FLAG in its 8-digit ID)."""
    parts = line.split()
    ident = parts[2].partition("#")[0] if len(parts) >= 3 else ""
    try:
        return len(ident) == 8 and bool(int(ident, 16) & CAN_ERR_FLAG)
    except ValueError:
        return False


def parse_line(line: str, line_number: int) -> LogEntry:
    """Read one log line.

    :raises CandumpError: naming the line, what was expected and what came.
    """
    parts = line.split()
    if len(parts) not in (3, 4):
        raise CandumpError(
            f"expected '(time) interface ID#DATA [R|T]', got {line.strip()[:60]!r}", line_number
        )
    stamp, channel, body = parts[0], parts[1], parts[2]
    if not (stamp.startswith("(") and stamp.endswith(")")):
        raise CandumpError(f"expected a time stamp like (1.5), got {stamp[:30]!r}", line_number)
    try:
        ts = float(stamp[1:-1])
    except ValueError:
        ts = math.nan
    if not math.isfinite(ts):
        raise CandumpError(f"expected a finite number in the time stamp, got {stamp[:30]!r}",
                           line_number)
    ident, sep, payload = body.partition("#")
    if not sep or len(ident) not in (3, 8):
        raise CandumpError(f"expected ID#DATA with a 3- or 8-digit ID, got {body[:40]!r}",
                           line_number)
    if not all(c in _HEX for c in ident):
        raise CandumpError(f"expected a hexadecimal ID, got {ident!r}", line_number)
    can_id = int(ident, 16)
    extended = len(ident) == 8
    if can_id > (0x1FFFFFFF if extended else 0x7FF):
        raise CandumpError(f"ID {ident} is out of range", line_number)
    if payload[:1] in ("R", "r"):
        rest = payload[1:]
        if rest and not (rest.isdigit() and int(rest) <= 8):
            raise CandumpError(f"expected R or R0..R8 for a remote frame, got {payload!r}",
                               line_number)
        frame = Frame(can_id, b"", extended, True, int(rest) if rest else 0, ts)
    else:
        if payload.startswith("#"):
            raise CandumpError("CAN FD frames are not supported", line_number)
        try:
            data = bytes.fromhex(payload)
        except ValueError:
            raise CandumpError(f"expected hexadecimal data, got {payload[:40]!r}",
                               line_number) from None
        if len(data) > 8:
            raise CandumpError(f"expected at most 8 data bytes, got {len(data)}", line_number)
        frame = Frame(can_id, data, extended, False, len(data), ts)
    direction = parts[3] if len(parts) == 4 else "R"
    if direction not in ("R", "T"):
        raise CandumpError(f"expected direction R or T, got {direction!r}", line_number)
    return LogEntry(ts, channel, frame, direction == "R")


def read_lines(
    lines: Iterable[str], errors: list[CandumpError] | None = None
) -> Iterator[LogEntry]:
    """Every readable entry of ``lines``; unreadable ones are appended to ``errors`` (or
    raised when ``errors`` is ``None``).  Blank lines and ``#`` comments are skipped."""
    for number, line in enumerate(lines, start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            yield parse_line(line, number)
        except CandumpError as err:
            if errors is None:
                raise
            errors.append(err)
