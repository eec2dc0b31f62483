"""ODrive axes on a scan (:class:`OdriveProbe`, ``wheelgate scan``).

Found by their **heartbeat** (command 0x01, ``node_id << 5 | 1``, DLC 8, sent every 100 ms
from the factory: ``heartbeat_rate_ms`` / ``heartbeat_msg_rate_ms``), in 11-bit or 29-bit
identifiers, when byte 4 is an axis state.  Bytes 0..4 (axis error, axis state) mean the same in
0.5 and 0.6; bytes 5..7 differ, so only 0.6 axes, which say so, get their procedure result read.

**One request per axis: Get_Version** (command 0x00) as an RTR frame, the way the protocol asks
for any ``Get_*`` message (ODrive CAN protocol, docs.odriverobotics.com, can-protocol: "Get_Version
... RTR").  It reads and changes nothing but the axis watchdog: 0.6 feeds it only with
Set_Input_* and Set_Axis_State (as :mod:`drivers.odrive.sim` reads it), but 0.5 feeds it with any
frame addressed to the axis, this one included (``do_command`` calls ``axis.watchdog_feed()``
before its switch, odriverobotics/ODrive ``Firmware/communication/can/can_simple.cpp``); a feed
clears nothing (a WATCHDOG_TIMER_EXPIRED already latched stays in the heartbeat).  Firmware 0.6
answers with its firmware and hardware versions; 0.5 has no Get_Version (command 0x00 is
reserved for CANopen NMT there, in the same ``can_simple.cpp``) and stays silent, so an axis that
does not answer is reported as probably 0.5, with its error word in hex (the flags' names differ
between the families).  A running gateway's ODrive driver ignores the version answers unless it
is arming that axis, when the answer is the same one it asked for.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from drivers.odrive.codec import OdriveCodec
from drivers.odrive.enums import AxisError, AxisState, CmdId, Firmware, flag_names
from drivers.odrive.messages import CMD_BITS, CMD_MASK, EncoderEstimates, Heartbeat
from drivers.odrive.watchdog import parse_version
from gateway.core.errors import DecodeError
from gateway.drive.scan import Description, Found, Request, ScanProbe

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.core.types import Frame
    from gateway.drive.scan import Answer, Heard, Reading

#: The key of the Get_Version request.
GET_VERSION = "Get_Version"


class OdriveProbe(ScanProbe):
    """ODrive CANSimple axes (0.5 and 0.6), by heartbeat; Get_Version asked (see the module)."""

    PROTOCOL: ClassVar[str] = "odrive"
    TITLE: ClassVar[str] = "ODrive"
    DRIVER: ClassVar[str] = "odrive"
    #: Last: a heartbeat identifier is any identifier ending in 0b00001, so the protocols with
    #: narrower tests (CANopen heartbeats, DJI feedback, VESC status) claim theirs first.
    PRECEDENCE: ClassVar[int] = 40

    def __init__(self) -> None:
        # The 0.6 codec reads the bytes both families share (0..4) the same way.
        self._codecs = {False: OdriveCodec(Firmware.V0_6, False),
                        True: OdriveCodec(Firmware.V0_6, True)}

    def _decode(self, frame: Frame) -> object:
        try:
            return self._codecs[frame.is_extended_id].decode(frame)
        except DecodeError:
            return None

    def find(self, heard: Sequence[Heard]) -> list[Found]:
        out = []
        for h in heard:
            if h.last is None or h.arbitration_id & CMD_MASK != CmdId.HEARTBEAT:
                continue
            hb = self._decode(h.last)
            if isinstance(hb, Heartbeat) and isinstance(hb.axis_state, AxisState):
                out.append(Found(hb.node_id, h.is_extended_id, "heartbeat"))
        return out

    def owns(self, found: Found, arbitration_id: int, extended: bool) -> bool:
        return extended == found.extended and arbitration_id >> CMD_BITS == found.node_id

    def requests(self, found: Found, heard: Sequence[Heard]) -> tuple[Request, ...]:
        codec = self._codecs[found.extended]
        ask = codec.make_request(found.node_id, CmdId.GET_VERSION)
        return (Request(GET_VERSION, found.node_id, ask, ask.arbitration_id, found.extended,
                        answer_dlc=8),)

    def describe(self, found: Found, heard: Sequence[Heard],
                 answers: Sequence[Answer]) -> Description:
        hb: Heartbeat | None = None
        readings: list[Reading] = []
        for h in heard:
            msg = None if h.last is None else self._decode(h.last)
            if isinstance(msg, Heartbeat):
                hb = msg
            elif isinstance(msg, EncoderEstimates):
                readings += [("position_turns", msg.pos_turns),
                             ("velocity_turns_s", msg.vel_turns_s)]
        version = next((parse_version(a.frame.data) for a in answers
                        if a.request.key == GET_VERSION and a.frame is not None), None)
        notes = []
        if version is None and any(a.request.key == GET_VERSION for a in answers):
            notes.append("no answer to Get_Version: firmware 0.5 (which has none), or an axis "
                         "that is not an ODrive")
            if hb is not None and hb.axis_state == AxisState.UNDEFINED:
                # 0 is a value one requests ("fall through to idle"), never a state an axis
                # reports: with no version either, another protocol's frame is likelier.
                notes.append("doubtful: its heartbeat says axis state UNDEFINED (0), which an "
                             "ODrive never reports; probably another controller's frame (give "
                             "the robot's configuration, -c, to name its frames)")
        state = errors = None
        if hb is not None:
            state = hb.axis_state.name if isinstance(hb.axis_state, AxisState) else str(
                hb.axis_state)
            if not hb.axis_error:
                errors = "none"
            elif version is not None:
                errors = flag_names(AxisError, hb.axis_error)
            else:
                errors = f"0x{hb.axis_error:08X}"
            if version is not None:
                readings.append(("procedure_result", str(getattr(hb.procedure_result, "name",
                                                                 hb.procedure_result))))
        fw, hw = version if version is not None else (None, None)
        return Description(state=state, errors=errors, firmware=fw, hardware=hw,
                           readings=tuple(readings), notes=tuple(notes))
