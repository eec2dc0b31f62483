"""DJI RoboMaster ESCs on a scan (:class:`DjiProbe`, ``wheelgate scan``).

A C620 / C610 sends its **feedback** unasked, about 1000 times a second, on ``0x200 + ESC ID``
(0x201..0x208; a GM6020 uses 0x205..0x20B): rotor angle, speed, current, temperature, DLC 8
(:func:`~drivers.dji.codec.feedback_fields`).  The protocol has no request, no heartbeat and
no version, so **nothing is sent**: the scan reports the ESC ID (the node ID here) and the
latest feedback.

0x201 and 0x209 are also an ODrive's at node 16 (its heartbeat and its encoder estimates):
they count as DJI feedback only beside another DJI feedback identifier, or (0x201) at a DJI
rate, :data:`MIN_FEEDBACK_HZ` or more.  Once a DJI ESC is found, no other protocol's request
goes to the command identifiers 0x1FE, 0x1FF, 0x200, 0x2FE, 0x2FF, nor to 0x700 (which puts a
C620 into quick ID-setting mode).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from drivers.dji.codec import (
    COMMAND_IDS,
    ESC_ID_MAX,
    ESCS_PER_GROUP,
    FEEDBACK_ID_BASE,
    DjiFrameId,
    feedback_fields,
)
from gateway.core.errors import DecodeError
from gateway.drive.scan import Description, Found, ScanProbe

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.drive.scan import Answer, Heard

#: Feedback identifiers: ESC 1..8 (C620, C610), and up to 0x20B for a GM6020's IDs 5..7.
FEEDBACK_IDS = range(FEEDBACK_ID_BASE + 1, 0x20B + 1)
#: The feedback identifiers that an ODrive at node 16 also uses (heartbeat, estimates).
SHARED_WITH_ODRIVE = frozenset({0x201, 0x209})
#: The slowest feedback (frames/s) that shows a DJI ESC on 0x201 alone: an ESC sends about
#: 1000, an ODrive heartbeat 10 (factory setting).
MIN_FEEDBACK_HZ = 150.0
#: The command identifiers of C620/C610 (0x200, 0x1FF) and GM6020 (0x1FE, 0x2FE, 0x2FF) ESCs.
COMMAND_GROUPS = (*COMMAND_IDS, 0x1FE, 0x2FE, 0x2FF)
_RESERVED = frozenset({*COMMAND_GROUPS, int(DjiFrameId.QUICK_ID_SET)})


def _feedback(heard: Heard) -> tuple[int, int, int, int, int] | None:
    frame = heard.last
    if heard.is_extended_id or heard.arbitration_id not in FEEDBACK_IDS or frame is None:
        return None
    try:
        return feedback_fields(frame)
    except DecodeError:
        return None


class DjiProbe(ScanProbe):
    """DJI C620/C610 (and GM6020) ESCs, by feedback; nothing asked (see the module)."""

    PROTOCOL: ClassVar[str] = "dji"
    TITLE: ClassVar[str] = "DJI"
    DRIVER: ClassVar[str] = "dji"
    PRECEDENCE: ClassVar[int] = 20

    def find(self, heard: Sequence[Heard]) -> list[Found]:
        feedback = [h for h in heard if _feedback(h) is not None]
        beside = any(h.arbitration_id not in SHARED_WITH_ODRIVE for h in feedback)
        return [Found(h.arbitration_id - FEEDBACK_ID_BASE, False, "feedback") for h in feedback
                if beside or (h.arbitration_id == 0x201 and h.rate_hz >= MIN_FEEDBACK_HZ)]

    def owns(self, found: Found, arbitration_id: int, extended: bool) -> bool:
        if extended:
            return False
        if arbitration_id == FEEDBACK_ID_BASE + found.node_id:
            return True
        # The command frame that carries this ESC's slot.
        k = found.node_id
        return k <= ESC_ID_MAX and arbitration_id == COMMAND_IDS[(k - 1) // ESCS_PER_GROUP]

    def reserved(self, arbitration_id: int, extended: bool) -> bool:
        return not extended and arbitration_id in _RESERVED

    def describe(self, found: Found, heard: Sequence[Heard],
                 answers: Sequence[Answer]) -> Description:
        fields = next((f for h in heard if (f := _feedback(h)) is not None), None)
        readings: tuple[tuple[str, float | int | str], ...] = ()
        if fields is not None:
            angle, speed, current, temperature, _ = fields
            readings = (("angle_count", angle), ("speed_rpm", speed), ("current_raw", current),
                        ("temperature_c", temperature))
        k = found.node_id
        kind = f"ESC ID {k}" if k <= ESC_ID_MAX else f"GM6020 ID {k - 4}"
        return Description(readings=readings, notes=(kind,))
