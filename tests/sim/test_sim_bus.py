"""The simulated controllers on a bus (:mod:`gateway.sim.bus`) answer a frame as a real
controller does: as of the time it came, however late the simulator's process gets to it."""

from __future__ import annotations

import math
import time

import can

from drivers.odrive.codec import OdriveCodec
from drivers.odrive.enums import CmdId
from drivers.odrive.messages import EncoderEstimates
from drivers.odrive.sim import OdriveSimulator
from gateway.bus.can_bus import to_message
from gateway.core.types import Frame
from gateway.sim.bus import SimulatedControllers
from tests.factories import motor

SPEED_RAD_S = 100.0  # the motor's at the start
WAIT_S = 0.05  # how long the request waits in the simulator's queue (at least)


def _answer(peer: can.BusABC) -> float:
    """The encoder estimate (rad at the motor) in the simulator's answer."""
    codec = OdriveCodec.from_options({})
    while (msg := peer.recv(1.0)) is not None:
        got = codec.decode(Frame(msg.arbitration_id, bytes(msg.data), msg.is_extended_id,
                                 msg.is_remote_frame, msg.dlc))
        if isinstance(got, EncoderEstimates):
            return got.pos_turns * 2 * math.pi
    raise AssertionError("no encoder estimates came back")


def test_a_request_that_waited_is_answered_with_the_position_when_it_came(
        channel: str) -> None:
    """An RTR for the encoder estimates waits 50 ms or more before the next real-time step
    (a starved process): the answer holds the position at the request, not that of 50 ms of
    turning later (and the next answer then steps by the whole wait at once)."""
    sim = OdriveSimulator(motor("odrive", 1), encoder_period_s=0.0,
                          heartbeat_period_s=3600.0)
    model = sim.model
    model.armed, model.target_rad_s, model.velocity_rad_s = True, SPEED_RAD_S, SPEED_RAD_S
    ctl = SimulatedControllers([sim], channel)
    peer = can.Bus(interface="virtual", channel=channel)
    try:
        ctl.step(time.monotonic(), real_time=True)  # the motor's clock starts
        before = model.position_rad
        request = OdriveCodec.from_options({}).make_request(1, CmdId.GET_ENCODER_ESTIMATES)
        peer.send(to_message(request))
        time.sleep(WAIT_S)
        ctl.step(time.monotonic(), real_time=True)
        answered, after = _answer(peer), model.position_rad
        # (The axis is IDLE: the motor coasts down from its speed, most of its turning early
        # in the wait; the request came within a few ms of its start.)
        assert after - before > 1.0
        assert before <= answered < before + 0.2 * (after - before)
    finally:
        peer.shutdown()
        ctl.shutdown()
