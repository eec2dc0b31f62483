"""The bus's own health: error frames by class, the controller's error state, bursts the bus
could not take, throttled logs and reopen backoff (pure), and what the loop makes of them on
the virtual bus.  The same faults on a kernel bus are in ``test_socketcan_faults.py``."""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import can
import pytest

from gateway.bus.health import (
    NO_ROOM_TEXT,
    Backoff,
    BurstTracker,
    BusErrors,
    ControllerStatus,
    ErrorClass,
    ErrorFrame,
    LogThrottle,
    bus_off_restart,
    unsent_why,
)
from gateway.core.control import AUTO_RETRIES, AUTO_RETRY_DELAY_S, Source
from gateway.core.status import BusErrorState
from gateway.core.types import ErrorCode, Frame, GatewayState, Twist
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, error_frame, virtual_config

if TYPE_CHECKING:
    from collections.abc import Iterator

# -- decoding (values of include/uapi/linux/can/error.h) ---------------------------------------


@pytest.mark.parametrize(("can_id", "data", "classes", "state", "text"), [
    (0x040, bytes(8), ErrorClass.BUS_OFF, BusErrorState.BUS_OFF, "bus-off"),
    (0x100, bytes(8), ErrorClass.RESTARTED, BusErrorState.ACTIVE, "controller restarted"),
    (0x004, bytes([0, 0x20, 0, 0, 0, 0, 0, 0]), ErrorClass.CONTROLLER, BusErrorState.PASSIVE,
     "controller problem (TX_PASSIVE)"),
    (0x004, bytes([0, 0x04, 0, 0, 0, 0, 0, 0]), ErrorClass.CONTROLLER, BusErrorState.WARNING,
     "controller problem (RX_WARNING)"),
    (0x004, bytes([0, 0x40, 0, 0, 0, 0, 0, 0]), ErrorClass.CONTROLLER, BusErrorState.ACTIVE,
     "controller problem (ACTIVE)"),
    (0x004, bytes([0, 0x01, 0, 0, 0, 0, 0, 0]), ErrorClass.CONTROLLER, None,
     "controller problem (RX_OVERFLOW)"),
    (0x020, bytes(8), ErrorClass.NO_ACK, None, "no ACK"),
    (0x088, bytes(8), ErrorClass.PROTOCOL | ErrorClass.BUS_ERROR, None,
     "protocol violation, bus error"),
    (0x204, bytes([0, 0x08, 0, 0, 0, 0, 97, 3]), ErrorClass.CONTROLLER | ErrorClass.COUNTERS,
     BusErrorState.WARNING, "error counters tx 97 rx 3"),
])
def test_error_frames_are_decoded_by_class(
    can_id: int, data: bytes, classes: ErrorClass, state: BusErrorState | None, text: str
) -> None:
    frame = ErrorFrame.decode(can_id, data)
    assert frame.classes == classes
    assert frame.state() is state
    assert text in frame.describe()


def test_a_short_error_frame_reads_as_zeros() -> None:
    frame = ErrorFrame.decode(0x004, b"")
    assert frame.controller == ControllerStatus(0)
    assert frame.state() is None


def test_bus_off_lasts_until_a_restart() -> None:
    errors = BusErrors()
    warning = ErrorFrame.decode(0x004, bytes([0, 0x08] + [0] * 6))
    assert errors.take(warning) is BusErrorState.WARNING
    assert errors.take(ErrorFrame.decode(0x040, bytes(8))) is BusErrorState.BUS_OFF
    # A passive report while bus-off does not lift it; a restart does.
    assert errors.take(ErrorFrame.decode(0x004, bytes([0, 0x20] + [0] * 6))) is None
    assert errors.state is BusErrorState.BUS_OFF
    assert errors.take(ErrorFrame.decode(0x100, bytes(8))) is BusErrorState.ACTIVE
    assert errors.counts["error_frames"] == 4
    assert (errors.counts["bus_off"], errors.counts["controller"], errors.counts["restarted"]) \
        == (1, 2, 1)
    assert errors.last == "controller restarted"


# -- bursts, logs, backoff -------------------------------------------------------------------


def _frames(*ids: int) -> list[Frame]:
    return [Frame(i, b"\0") for i in ids]


def test_frames_left_out_go_first_and_a_starving_one_is_reported() -> None:
    tracker = BurstTracker(fault_after=3)
    burst = _frames(1, 2, 3, 4)
    assert tracker.order(burst) is burst  # nothing left out yet: the burst as it is
    assert tracker.after_send(burst, 2) is None
    assert [f.arbitration_id for f in tracker.order(burst)] == [3, 4, 1, 2]
    assert tracker.after_send(tracker.order(burst), 2) is None  # 3 and 4 went out
    assert tracker.missed == {(1, False): 1, (2, False): 1}
    # A frame that is not in a burst keeps its count (the reports go in bursts of their own).
    assert tracker.after_send(_frames(9), 1) is None
    assert tracker.missed == {(1, False): 1, (2, False): 1}
    tracker.after_send(burst, 0)
    assert tracker.after_send(burst, 0) == ((1, False), 3)
    tracker.after_send(burst, 4)
    assert tracker.missed == {}


@pytest.mark.parametrize("n", [2, 3, 4, 6, 8])
@pytest.mark.parametrize("room", [1, 2, 3, 5])
def test_with_room_for_k_of_n_frames_each_goes_out_every_ceil_n_over_k_bursts(
    n: int, room: int
) -> None:
    # A queue that takes the same number of frames every cycle: no frame waits longer than
    # its turn (round robin), whatever the burst's own order.
    tracker = BurstTracker(fault_after=1000)
    burst = _frames(*range(1, n + 1))
    last = dict.fromkeys(range(1, n + 1), -1)
    longest = 0
    for cycle in range(60):
        ordered = tracker.order(burst)
        tracker.after_send(ordered, room)
        for f in ordered[:room]:
            longest = max(longest, cycle - last[f.arbitration_id])
            last[f.arbitration_id] = cycle
    assert longest <= -(-n // room), (n, room, longest)
    assert min(last.values()) >= 60 - -(-n // room)


def test_a_log_line_per_interval_with_the_count() -> None:
    throttle = LogThrottle(5.0)
    assert throttle.note(0.0) == 1
    assert [throttle.note(t / 10) for t in range(1, 50)] == [None] * 49
    assert throttle.note(5.0) == 50
    assert throttle.total == 51


#: Every wording of a full transmit queue among python-can's interfaces that give no errno
#: (SocketCAN's send timeout, PCAN-Basic's QXMTFULL and XMTFULL, SYSTEC's, Kvaser's
#: canERR_TXBUFOFL, Neousys's), and send errors that are not one.
FULL_WORDS = ["Transmit buffer full", "Failed to send: Transmit queue is full",
              "Failed to send: Transmit buffer in CAN controller is full", "Tx-buffer is full",
              "a CAN message did not fit into the transmit buffer",
              "Transmit buffer overflow (-13)", "Neousys message Queue is full"]
OTHER_WORDS = ["Failed to transmit: Network is down", "Failed to send: Bus-off",
               "Cannot send on a closed bus", "Rx-buffer is full",
               "Receive queue was read too late"]


@pytest.mark.parametrize("words", FULL_WORDS + OTHER_WORDS)
def test_a_full_transmit_queue_is_known_by_its_words_without_an_errno(words: str) -> None:
    assert (NO_ROOM_TEXT.search(words) is not None) == (words in FULL_WORDS)


def test_what_to_check_names_the_interface() -> None:
    assert unsent_why("socketcan", "can0", "Network is down").endswith(
        "check that can0 is up (ip link show can0)")
    assert unsent_why("pcan", "PCAN_USBBUS1", "Failed to send: Illegal hardware").endswith(
        "check that the pcan interface PCAN_USBBUS1 is connected")
    full = unsent_why("pcan", "PCAN_USBBUS1", None)
    assert full.startswith("the CAN transmit queue stays full (no other node acknowledges")
    assert "txqueuelen" not in full and "txqueuelen" in unsent_why("socketcan", "can0", None)
    assert "restart-ms 100" in bus_off_restart("socketcan", "can0")
    assert bus_off_restart("pcan", "PCAN_USBBUS1") == ""


def test_reopen_backoff_doubles_and_resets() -> None:
    backoff = Backoff(0.1, 1.0)
    assert backoff.due(0.0)
    assert [backoff.failed(t) for t in (0.0, 0.1, 0.3, 0.7, 1.5, 2.5)] == [
        0.1, 0.2, 0.4, 0.8, 1.0, 1.0]
    assert not backoff.due(3.4)
    assert backoff.due(3.5)
    backoff.reset()
    assert backoff.failed(10.0) == 0.1


# -- the loop on the virtual bus ---------------------------------------------------------------


@pytest.fixture
def rig(channel: str) -> Iterator[Rig]:
    cfg = virtual_config(CONFIG_DIR / "turtlebot3_burger.yaml", channel, rate_hz=100.0)
    with Rig(cfg) as r:
        r.enable()
        yield r


_SOCKET = Source.SOCKET


def state(rig: Rig) -> GatewayState:
    return rig.gw.state


def test_bus_off_is_a_fault_that_names_it_and_the_restart_lets_it_recover(
    rig: Rig, caplog: pytest.LogCaptureFixture
) -> None:
    rig.gw.twist(Twist(0.1), rig.t, _SOCKET)
    rig.advance(0.3)
    with caplog.at_level(logging.WARNING, logger="gateway.runtime.loop"):
        rig.pilot.send(error_frame(0x004, bytes([0, 0x20, 0, 0, 0, 0, 0, 0])))  # passive
        rig.advance(0.05)
        assert state(rig) is GatewayState.RUNNING  # error passive: counted, not a fault
        assert rig.gw.edge.bus_errors.state is BusErrorState.PASSIVE
        rig.pilot.send(error_frame(0x040))
        rig.advance(0.05)
    sup = rig.gw.supervisor
    assert state(rig) is GatewayState.FAULT
    assert sup.fault_code is ErrorCode.BUS_ERROR
    assert "CAN bus-off on virtual:" in sup.reason
    assert not rig.gw.edge.bus_healthy
    assert [s.model.target_rad_s for s in rig.drive_sims] == [0.0, 0.0]
    assert rig.gw.status_report().flags
    # Still bus-off: no automatic recovery, however long the motors answer, and no retry
    # is spent on it (the recovery after the restart below still has all of them).
    rig.advance(sum(AUTO_RETRY_DELAY_S * (k + 1) for k in range(AUTO_RETRIES + 1)) + 1.0)
    assert sup.counts.faults == 1
    assert state(rig) is GatewayState.FAULT
    rig.pilot.send(error_frame(0x100))  # the controller restarted (restart-ms)
    rig.advance(3 * AUTO_RETRY_DELAY_S + 1.0)
    assert state(rig) is GatewayState.RUNNING
    counts = rig.gw.edge.bus_errors.counts
    assert (counts["error_frames"], counts["bus_off"], counts["restarted"]) == (3, 1, 1)
    assert rig.gw.edge.counts.frames_received > 0  # error frames are not the drivers' frames
    assert any("bus-off" in r.getMessage() for r in caplog.records)


def test_enabling_while_bus_off_is_refused_with_the_reason(rig: Rig) -> None:
    rig.gw.supervisor.disable()
    rig.advance(0.1)
    rig.pilot.send(error_frame(0x040))
    rig.advance(0.05)
    rig.gw.supervisor.enable(rig.t)
    rig.advance(0.05)
    assert state(rig) is GatewayState.FAULT
    assert "bus-off" in rig.gw.supervisor.reason


def test_can_fd_frames_are_ignored_and_counted(rig: Rig) -> None:
    rig.gw.twist(Twist(0.1), rig.t, _SOCKET)
    before = rig.gw.edge.counts.frames_received
    for can_id in (0x2D, 0x100, 0x7FF):  # even on the IDs of a motor and of the twist input
        rig.pilot.send(can.Message(arbitration_id=can_id, is_fd=True, data=bytes(range(64)),
                                   is_extended_id=False))
    rig.advance(0.2)
    assert rig.gw.edge.counts.fd_frames_ignored == 3
    assert rig.gw.counts.can_twists == 0
    assert rig.gw.edge.counts.frames_received > before
    assert state(rig) is GatewayState.RUNNING
