"""Frames the drivers reject are said in the log with the driver's reason, a line every few
seconds at most (:mod:`gateway.runtime.rejections`), and counted in the status."""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from drivers.odrive.enums import CmdId
from gateway.bus.can_bus import send_frames
from gateway.core.types import Frame
from gateway.runtime.rejections import INTERVAL_S
from tests.e2e_helpers import Rig, virtual_config
from tests.runtime.safety_helpers import TB3

if TYPE_CHECKING:
    import pytest


def test_a_malformed_controller_frame_is_said_with_its_reason(
    channel: str, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="gateway.runtime.loop")
    with Rig(virtual_config(TB3, channel, rate_hz=100.0)) as rig:
        rig.enable()
        node = rig.gw.config.motors[0]
        assert node is not None
        short = Frame(node.node_id << 5 | CmdId.GET_ENCODER_ESTIMATES, b"\x00\x00\x00")
        for _ in range(3):
            send_frames(rig.pilot, [short])
            rig.advance(0.05)
        lines = [r.getMessage() for r in caplog.records if "rejected" in r.getMessage()]
        # The first at once; the next two within the interval wait for the next line.
        assert lines == [
            "odrive rejected 1 frame (malformed) since the last report; the last: "
            "Expected 8 data bytes in Get_Encoder_Estimates of ODrive node 1 (ID 0x29), but "
            "got 3."]
        send_frames(rig.pilot, [short])
        rig.advance(INTERVAL_S + 0.5)
        lines = [r.getMessage() for r in caplog.records if "rejected" in r.getMessage()]
        assert len(lines) == 2 and lines[1].startswith("odrive rejected 3 frames (malformed)")
        rig.advance(INTERVAL_S + 0.5)  # nothing new: no line
        assert len([r for r in caplog.records if "rejected" in r.getMessage()]) == 2
