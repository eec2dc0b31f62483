"""The :class:`MotorCodec` ABC: the pure half of every protocol driver.

A codec turns native command values into frames and frames into native feedback.  It does no
I/O, takes no locks, never sleeps and never reads the clock (the moteus ``make_*`` idea).
Unit conversion to and from wheel rad/s belongs to the stateful driver
(:class:`gateway.drive.driver.MotorDriver`).
"""

from __future__ import annotations

import abc
from typing import TYPE_CHECKING, Generic, TypeVar

if TYPE_CHECKING:
    from collections.abc import Mapping

    from gateway.core.types import Frame

FeedbackT = TypeVar("FeedbackT")


class MotorCodec(abc.ABC, Generic[FeedbackT]):
    """Pure encoder and decoder of one protocol.

    Subclasses describe each message once as data (a precompiled ``struct.Struct`` and a scale
    per field) and raise :class:`gateway.core.errors.EncodeError` for values out of range.
    """

    @abc.abstractmethod
    def encode_command(self, commands: Mapping[int, float]) -> tuple[Frame, ...]:
        """Frames that command the given controllers.

        :param commands: node ID -> command in the protocol's native unit (turns/s for ODrive,
            eRPM for VESC, device velocity units for CiA 402, raw current for DJI).
        :return: the frames, in a fixed order; a protocol that packs several controllers into
            one frame (DJI) returns fewer frames than commands.
        :raises EncodeError: if a value is out of the field's range or not finite.
        """

    @abc.abstractmethod
    def decode(self, frame: Frame) -> FeedbackT | None:
        """Decode one received frame.

        :param frame: any frame seen on the bus.
        :return: the decoded message, or ``None`` if the frame is not this protocol's.
        :raises DecodeError: if the frame is this protocol's but malformed (wrong DLC, wrong ID
            type, impossible value).  Drivers catch it, count it and go on.
        """
