"""Liveness of a driver's motors: each motor is alive while every stream it must hear is young.

A protocol names its streams (:attr:`~gateway.drive.driver.MotorDriver.LIVENESS_STREAMS`): the
feedback alone for most, the heartbeat and the encoder estimates for an ODrive (the heartbeat
gives the state, the estimates the odometry).  A motor is alive while the oldest of its
streams is younger than ``liveness_s``.  Pure: the caller passes the times.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Sequence


class Liveness:
    """When each motor's streams were last heard.

    :param motors: the number of motors.
    :param streams: the names of the streams every motor must keep up.
    :param liveness_s: the age (s) beyond which a silent stream makes its motor OFFLINE.
    """

    __slots__ = ("liveness_s", "oldest", "streams", "times")

    def __init__(self, motors: int, streams: Sequence[str], liveness_s: float) -> None:
        self.streams = tuple(streams)
        self.liveness_s = liveness_s
        #: Per motor, the last time each stream was heard (``None``: never).
        self.times: list[list[float | None]] = [[None] * len(self.streams) for _ in range(motors)]
        #: Per motor, the oldest of its streams' times (``None`` until every one was heard):
        #: what :meth:`alive` compares, kept up to date by :meth:`heard`.
        self.oldest: list[float | None] = [None] * motors

    def heard(self, index: int, stream: int, t: float) -> None:
        """Motor ``index``'s stream ``stream`` was heard at ``t``."""
        times = self.times[index]
        times[stream] = t
        if len(times) == 1:
            self.oldest[index] = t
            return
        oldest: float | None = t
        for s in times:
            if s is None:
                oldest = None
                break
            if oldest is not None and s < oldest:
                oldest = s
        self.oldest[index] = oldest

    def alive(self, index: int, now_s: float) -> bool:
        """Whether every stream of motor ``index`` is younger than ``liveness_s``."""
        oldest = self.oldest[index]
        return oldest is not None and now_s - oldest <= self.liveness_s

    def silent(self, index: int, now_s: float) -> list[str]:
        """The names of motor ``index``'s streams that are missing or too old."""
        return [
            name for name, t in zip(self.streams, self.times[index], strict=True)
            if t is None or now_s - t > self.liveness_s
        ]
