"""The time line of a candump log: lines out of time, and breaks in the recording.

A log's time stamps are the recording computer's wall clock (``candump -l``: the kernel's
receive time; ``wheelgate run --record``: ``time.time()``), so they can jump: a line whose
stamp is garbled, a clock set by NTP while recording (a robot without a real-time clock boots
hours or years behind), a recording paused or two logs joined.  The replay's update rule and the
odometry need a time that goes on: one stamp an hour ahead would make every later interval
negative, and the replay would integrate nothing more until the end of the log.

:class:`Timeline` holds every line's time against the log's time so far (the latest stamp of
the lines taken; a line *follows* it when it is at most :data:`MAX_STEP_BACK_S` before it and at
most :data:`MAX_GAP_S` after it).  A line that does not follow is judged by the next readable
line:

* when the next line follows the time before it, the line alone is out of time: a bad line
  (:class:`StampError`), skipped and reported as an unreadable line is (its number, its time,
  the time before it); so is a line that the next one does not follow either, the last line
  of a log (no line follows to confirm it), and a first line that the second goes back from;
* when the next line follows it instead, the log's time jumped and the recording goes on from
  there: a *break* (:class:`TimeBreak`), reported with its line, its time and the time before
  it.

A break forward keeps the log's times: the odometry integrates across the gap as the gateway
does when the feedback pauses (the wheels' positions are absolute, so the motion across it is
in the next sample; only the twist of that one interval, spread over the gap, means nothing).
Its length is left out of the log time replayed (:attr:`Timeline.gap_s`).  A break backward
cannot be time that passed: the replay's clock goes on from the time before it, as if none had
(the lines after it reach the drivers, the update rule and the odometry shifted by the step,
:attr:`Timeline.offset_s`, so the samples' times keep increasing).  A log without jumps passes
through unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.wire.candump import CandumpError, LogEntry, parse_line

if TYPE_CHECKING:
    from collections.abc import Iterable, Iterator

__all__ = ["MAX_GAP_S", "MAX_STEP_BACK_S", "StampError", "TimeBreak", "Timeline"]

#: A line further than this after the log's time so far is a jump, s.  The gateway sends every
#: control period while it runs and the controllers stream their feedback at tens of hertz, so
#: a second without a line is no pause of a robot at work: the recording stopped, or its clock
#: was set.
MAX_GAP_S = 1.0
#: A line up to this before the log's time so far still follows it, s: frames of two interfaces
#: merged in one log (``candump -l any``) come in the order their sockets were read, a few
#: milliseconds apart at worst; the replay takes them as they come, as before.
MAX_STEP_BACK_S = 0.01


class StampError(CandumpError):
    """A line whose time stamp does not follow the lines around it (skipped).

    :param line_number: 1-based line number.
    :param time_s: its time stamp, s (the log's own).
    :param previous_s: the log's time before it, s; for a first line, the next line's.
    :param max_gap_s: the largest step forward that follows, s.
    :param first: whether it is the first line (held against the next one).
    """

    def __init__(self, line_number: int, time_s: float, previous_s: float,
                 max_gap_s: float = MAX_GAP_S, first: bool = False) -> None:
        step = time_s - previous_s
        if first:
            want = f"no later than the next line's ({previous_s:.6f})"
        elif step > 0:
            want = f"at most {max_gap_s:g} s after the log's time before it ({previous_s:.6f})"
        else:
            want = f"no earlier than the log's time before it ({previous_s:.6f})"
        how = f"{step:.3f} s later" if step > 0 else f"{-step:.3f} s earlier"
        super().__init__(f"expected a time stamp {want}, got ({time_s:.6f}), {how}",
                         line_number)
        self.time_s = time_s
        self.previous_s = previous_s


@dataclass(frozen=True, slots=True)
class TimeBreak:
    """A jump of the log's time that the line after it goes on from.

    :param line_number: the first line after the jump, 1-based.
    :param time_s: its time stamp, s (the log's own).
    :param previous_s: the log's time before it, s.
    """

    line_number: int
    time_s: float
    previous_s: float

    def __str__(self) -> str:
        step = self.time_s - self.previous_s
        jump = (f"jumps {step:.3f} s forward" if step > 0 else f"goes {-step:.3f} s back")
        what = ("a break in the recording: the odometry integrates across it" if step > 0
                else f"its clock was set back: the replay's clock goes on from "
                     f"({self.previous_s:.6f})")
        return (f"line {self.line_number}: the log's time {jump}, from ({self.previous_s:.6f}) "
                f"to ({self.time_s:.6f}), and goes on from there ({what})")


def _shifted(entry: LogEntry, offset_s: float) -> LogEntry:
    t = entry.timestamp_s + offset_s
    return LogEntry(t, entry.channel, entry.frame._replace(timestamp_s=t), entry.is_rx)


class Timeline:
    """Takes a log's entries in order and passes on those in time (see the module's doc).

    :param max_gap_s: the largest step forward that follows, s (:data:`MAX_GAP_S`).
    :param max_step_back_s: the largest step back that follows, s (:data:`MAX_STEP_BACK_S`).
    :raises ValueError: if ``max_gap_s`` is not positive and finite, or ``max_step_back_s`` is
        negative or not finite.
    """

    def __init__(self, max_gap_s: float = MAX_GAP_S,
                 max_step_back_s: float = MAX_STEP_BACK_S) -> None:
        if not 0.0 < max_gap_s < math.inf:
            raise ValueError(f"Expected max_gap_s > 0 s and finite, but got {max_gap_s!r}")
        if not 0.0 <= max_step_back_s < math.inf:
            raise ValueError(f"Expected max_step_back_s >= 0 s and finite, but got "
                             f"{max_step_back_s!r}")
        self.max_gap_s = max_gap_s
        self.max_step_back_s = max_step_back_s
        #: Lines skipped as out of time, in order.
        self.bad: list[StampError] = []
        #: The jumps the log goes on from, in order.
        self.breaks: list[TimeBreak] = []
        #: Log time the breaks forward jump over, s.
        self.gap_s = 0.0
        #: The replay's clock minus the log's (the steps back so far), s.
        self.offset_s = 0.0
        #: The latest time taken so far, on the replay's clock, s.
        self.latest_s = -math.inf

    def read(self, lines: Iterable[str], errors: list[CandumpError]) -> Iterator[LogEntry]:
        """The entries of a log's lines that are in time, on the replay's clock.

        :param lines: the log's lines, in order; blank lines and ``#`` comments are skipped and
            unreadable ones appended to ``errors``, as :func:`gateway.wire.candump.read_lines`
            does (read here, in the same loop: a replay's time goes mostly to this loop).
        """
        lo, hi = -self.max_step_back_s, self.max_gap_s
        held: LogEntry | None = None
        held_line = 0
        latest, offset = self.latest_s, self.offset_s
        for number, line in enumerate(lines, start=1):
            if not line.strip() or line.lstrip().startswith("#"):
                continue
            try:
                entry = parse_line(line, number)
            except CandumpError as err:
                errors.append(err)
                continue
            if held is not None:
                self.latest_s = latest
                taken = self._settle(held, held_line, entry)
                latest, offset = self.latest_s, self.offset_s
                held = None
                if taken is not None:
                    yield taken
            t = entry.timestamp_s + offset
            if lo <= t - latest <= hi:
                if t > latest:  # noqa: PLR1730 - faster than max(), once a line
                    latest = t
                yield entry if not offset else _shifted(entry, offset)
            else:  # the next line tells whether this one is out of time
                held, held_line = entry, number
        self.latest_s = latest
        if held is not None:
            if self.latest_s == -math.inf:  # the only line: nothing to hold it against
                self.latest_s = held.timestamp_s
                yield held
            else:
                self.bad.append(self._stamp_error(held_line, held.timestamp_s))

    def _stamp_error(self, line: int, log_s: float) -> StampError:
        return StampError(line, log_s, self.latest_s - self.offset_s, self.max_gap_s)

    def _settle(self, held: LogEntry, line: int, after: LogEntry) -> LogEntry | None:
        """Judge the held line by the line ``after`` it: the held one, on the replay's clock,
        when it is taken (a break, or the first line), ``None`` when it is out of time."""
        start = self.latest_s == -math.inf
        h, t = held.timestamp_s, after.timestamp_s  # the log's own times
        lo, hi = -self.max_step_back_s, self.max_gap_s
        if not start and lo <= t + self.offset_s - self.latest_s <= hi:
            self.bad.append(self._stamp_error(line, h))  # the log goes on from before it
            return None
        if lo <= t - h <= hi:  # the log goes on from it
            if not start:
                before = self.latest_s - self.offset_s
                self.breaks.append(TimeBreak(line, h, before))
                if h > before:
                    self.gap_s += h - before
                else:  # no time passed: from where the replay's clock was
                    self.offset_s = self.latest_s - h
            self.latest_s = h + self.offset_s
            return held if not self.offset_s else _shifted(held, self.offset_s)
        if start and t > h:  # a first line, then a jump forward: the jump is the next line's
            self.latest_s = h
            return held
        if start:  # a first line the log goes back from
            self.bad.append(StampError(line, h, t, self.max_gap_s, first=True))
        else:  # in step with neither
            self.bad.append(self._stamp_error(line, h))
        return None
