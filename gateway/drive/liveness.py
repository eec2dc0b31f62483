"""Liveness of a driver's motors: each motor is alive while every stream it must hear is young.

A protocol names its streams (:attr:`~gateway.drive.driver.MotorDriver.LIVENESS_STREAMS`): the
feedback alone for most, the heartbeat and the encoder estimates for an ODrive (the heartbeat
gives the state, the estimates the odometry).  A motor is alive while the oldest of its
streams is younger than its ``liveness_s``.  Pure: the caller passes the times.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, cast

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence


#: How far inside every motor's limit :meth:`Liveness.all_alive` keeps its shortcut (s): far
#: beyond the rounding of ``now - oldest <= limit`` against ``now <= oldest + limit``.
_MARGIN_S = 1e-6


def still_comes(heard_s: float, silent_s: float, limit_s: float) -> bool:
    """Whether a stream heard at ``heard_s`` still comes though another fell silent after
    ``silent_s``: heard more than half of ``limit_s`` later.  A node that went silent as a
    whole stops its streams together, and the one with the shorter period was merely heard
    last."""
    return heard_s > silent_s + limit_s / 2


class Liveness:
    """When each motor's streams were last heard.

    :param motors: the number of motors.
    :param streams: the names of the streams every motor must keep up.
    :param limits: per motor, the age (s) beyond which a silent stream makes it OFFLINE (its
        ``liveness_s``).
    """

    __slots__ = ("_calm_until", "limits", "oldest", "streams", "times")

    def __init__(self, motors: int, streams: Sequence[str], limits: Sequence[float]) -> None:
        self.streams = tuple(streams)
        #: Per motor, its ``liveness_s``.
        self.limits: list[float] = list(limits)
        if len(self.limits) != motors:
            raise ValueError(f"expected {motors} liveness limits, got {len(self.limits)}")
        #: Per motor, the last time each stream was heard (``None``: never).
        self.times: list[list[float | None]] = [[None] * len(self.streams) for _ in range(motors)]
        #: Per motor, the oldest of its streams' times (``None`` until every one was heard):
        #: what :meth:`alive` compares, kept up to date by :meth:`heard`.
        self.oldest: list[float | None] = [None] * motors
        #: Until when every motor is surely alive (:meth:`all_alive`): at most the earliest
        #: ``oldest + limit`` less :data:`_MARGIN_S`; lowered at once by :meth:`heard` when
        #: a stream's time goes back, raised only by :meth:`all_alive`.
        self._calm_until = -math.inf

    def heard(self, index: int, stream: int, t: float) -> None:
        """Motor ``index``'s stream ``stream`` was heard at ``t``."""
        times = self.times[index]
        times[stream] = t
        oldest: float | None = t
        if len(times) > 1:
            for s in times:
                if s is None:
                    oldest = None
                    break
                if oldest is not None and s < oldest:
                    oldest = s
        self.oldest[index] = oldest
        if oldest is None or oldest + self.limits[index] - _MARGIN_S < self._calm_until:
            self._calm_until = -math.inf  # (a time that went back: recomputed when asked)

    def age(self, index: int, t: float, stream: int | None, now_s: float) -> float:
        """The age at ``now_s`` of what motor ``index`` sent at ``t``, or of its stream
        ``stream`` (``None``: none) when that is older."""
        s = None if stream is None else self.times[index][stream]
        return now_s - (t if s is None or s >= t else s)

    def all_alive(self, now_s: float) -> bool:
        """Whether every motor is alive at ``now_s`` (:meth:`alive` of each, in one call that
        mostly compares one number: what the supervisor asks every cycle)."""
        if now_s <= self._calm_until:
            return True
        if None in self.oldest:
            return False
        pairs = list(zip(cast("list[float]", self.oldest), self.limits, strict=True))
        if not all(now_s - t <= limit for t, limit in pairs):
            return False
        self._calm_until = min(t + limit for t, limit in pairs) - _MARGIN_S
        return True

    def alive(self, index: int, now_s: float) -> bool:
        """Whether every stream of motor ``index`` is younger than its ``liveness_s``."""
        oldest = self.oldest[index]
        return oldest is not None and now_s - oldest <= self.limits[index]

    def silent(self, index: int, now_s: float) -> list[str]:
        """The names of motor ``index``'s streams that are missing or too old."""
        limit = self.limits[index]
        return [
            name for name, t in zip(self.streams, self.times[index], strict=True)
            if t is None or now_s - t > limit
        ]

    def silence(self, index: int, now_s: float, hints: Mapping[str, str]) -> str:
        """What motor ``index`` still sends and what it does not, when some of its streams are
        missing or too old and others are not ("" otherwise): for the message of a motor
        that is OFFLINE though it answers (``hints``: how to switch a stream on, by name, said
        for a stream never heard).  A stream counts as still coming by :func:`still_comes`,
        after the last of the silent ones.

        >>> live = Liveness(1, ("encoder estimates", "heartbeat"), [0.25])
        >>> live.heard(0, 1, 1.0)
        >>> live.silence(0, 1.1, {"encoder estimates": "switch them on"})
        'sends its heartbeat but no encoder estimates (none yet): switch them on'
        >>> live.heard(0, 0, 1.0)
        >>> live.heard(0, 1, 1.5)
        >>> live.silence(0, 1.5, {"encoder estimates": "switch them on"})
        'sends its heartbeat but no encoder estimates (none for 0.500 s)'
        """
        limit = self.limits[index]
        pairs = list(zip(self.streams, self.times[index], strict=True))
        silent = [(n, t) for n, t in pairs if t is None or now_s - t > limit]
        since = max((t for _, t in silent if t is not None), default=-math.inf)
        heard = [n for n, t in pairs
                 if t is not None and now_s - t <= limit and still_comes(t, since, limit)]
        if not heard or not silent:
            return ""
        said = [f"{n} (none for {now_s - t:.3f} s)" if t is not None  # (no hint: it came)
                else f"{n} (none yet)" + (f": {hints[n]}" if hints.get(n) else "")
                for n, t in silent]
        return f"sends its {' and '.join(heard)} but no {'; no '.join(said)}"

    @property
    def liveness_s(self) -> float:
        """The longest ``liveness_s`` of the motors (their one value on a protocol whose motors
        share it, :attr:`~gateway.drive.driver.MotorDriver.BUS_WIDE`); 0.0 without motors."""
        return max(self.limits, default=0.0)
