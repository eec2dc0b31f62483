"""The python-can edge's message pool: one ``can.Message`` per identifier, refilled per send,
and never one message twice in a burst or in the hands of a recorder."""

from __future__ import annotations

import ast
import errno
import time

import can
import pytest
from hypothesis import given
from hypothesis import strategies as st

from gateway.bus.can_bus import MessagePool, drain, open_bus, to_message
from gateway.core.errors import BusError
from gateway.core.types import Frame
from tests.conftest import REPO

frames = st.builds(
    Frame,
    st.sampled_from([0x06D, 0x08D, 0x317]),
    st.binary(min_size=0, max_size=8),
    st.booleans(),
)


def same(msg: can.Message, frame: Frame) -> bool:
    return msg.equals(to_message(frame), timestamp_delta=None)


@given(st.lists(st.lists(frames, max_size=6), max_size=6))
def test_every_burst_carries_exactly_its_frames(bursts: list[list[Frame]]) -> None:
    pool = MessagePool()
    for burst in bursts:
        msgs = pool.messages(burst)
        assert len({id(m) for m in msgs}) == len(msgs)  # never one message twice in a burst
        assert all(same(m, f) for m, f in zip(msgs, burst, strict=True))


def test_a_message_is_reused_for_its_identifier_and_refilled() -> None:
    pool = MessagePool()
    (first,) = pool.messages([Frame(0x06D, b"\x01\x02")])
    (again,) = pool.messages([Frame(0x06D, b"\x03\x04\x05")])
    assert again is first and bytes(again.data) == b"\x03\x04\x05" and again.dlc == 3
    (ext,) = pool.messages([Frame(0x06D, b"\x06", is_extended_id=True)])
    assert ext is not first and ext.is_extended_id and bytes(ext.data) == b"\x06"


def test_a_virtual_bus_delivers_what_was_sent_though_the_message_is_refilled() -> None:
    # python-can's virtual bus copies a message in send(): refilling it afterwards must not
    # change what the receiver got (the pool's premise).
    with can.Bus(interface="virtual", channel="pool") as tx, \
            can.Bus(interface="virtual", channel="pool") as rx:
        pool = MessagePool()
        for payload in (b"\x01", b"\x02\x03", b"\x04"):
            for msg in pool.messages([Frame(0x06D, payload)]):
                tx.send(msg)
        got = [rx.recv(1.0) for _ in range(3)]
    assert [bytes(m.data) for m in got if m is not None] == [b"\x01", b"\x02\x03", b"\x04"]


@pytest.mark.parametrize(("code", "says"), [
    (errno.EAFNOSUPPORT, "this kernel has no SocketCAN: load it (modprobe can_raw"),
    (errno.ENODEV, "there is no network interface 'can7' (ip -details link show"),
    (errno.EPERM, None),
])
def test_a_socketcan_bus_that_cannot_open_says_what_to_do(
    monkeypatch: pytest.MonkeyPatch, code: int, says: str | None
) -> None:
    # The two errors a first SocketCAN bus meets, as python-can raises them (an OSError, or
    # its CanInitializationError caused by one); any other error is passed on as it is.
    def refuse(**_: object) -> can.BusABC:
        raise can.CanInitializationError("cannot open") from OSError(code, "refused")

    monkeypatch.setattr(can, "Bus", refuse)
    with pytest.raises(BusError) as info:
        open_bus("socketcan", "can7")
    text = str(info.value)
    assert text.startswith("Cannot open CAN bus socketcan:can7: cannot open")
    assert (says in text) if says else text.endswith("cannot open"), text


@pytest.mark.parametrize("step_s", [0.6, -0.6])
def test_a_wall_clock_step_before_the_drain_makes_a_frame_neither_old_nor_new(
    step_s: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    """NTP steps the wall clock between the kernel's stamp (wall time) and the drain, which
    moves stamps onto the monotonic clock by the wall clock it reads: the frame would look
    0.6 s old (a motor "stopped answering") or 0.6 s from the future.  It is put within
    [the previous drain, now]."""
    rx = can.Bus(interface="virtual", channel="wall-step", receive_own_messages=False)
    tx = can.Bus(interface="virtual", channel="wall-step", receive_own_messages=False)
    try:
        since = time.monotonic()
        tx.send(can.Message(arbitration_id=0x029, data=bytes(8), is_extended_id=False))
        real = time.time
        monkeypatch.setattr(time, "time", lambda: real() + step_s)
        (frame,) = drain(rx, since_s=since)
        assert since <= frame.timestamp_s <= time.monotonic()
        if step_s > 0:
            assert frame.timestamp_s == since  # (not 0.6 s before it)
    finally:
        rx.shutdown()
        tx.shutdown()


def test_on_the_callers_clock_a_frame_keeps_its_own_stamp_inside_the_drains_span() -> None:
    """``drain(timestamp_s=...)``: a frame stamped on the caller's clock (a simulated device's
    send time, passed on by a virtual bus that keeps stamps) keeps it when it lies after the
    previous drain and not after now; any other frame is stamped now (a wall-clock stamp)."""
    rx = can.Bus(interface="virtual", channel="sim-clock", receive_own_messages=False)
    keeps = can.Bus(interface="virtual", channel="sim-clock", preserve_timestamps=True)
    wall = can.Bus(interface="virtual", channel="sim-clock")
    try:
        for stamp in (5.0, 4.0, 7.0, 7.5, 3.0):
            keeps.send(can.Message(timestamp=stamp, arbitration_id=0x029, data=bytes(8),
                                   is_extended_id=False))
        wall.send(can.Message(timestamp=5.0, arbitration_id=0x029, data=bytes(8),
                              is_extended_id=False))
        got = [f.timestamp_s for f in drain(rx, timestamp_s=7.0, since_s=4.0)]
        assert got == [5.0, 7.0, 7.0, 7.0, 7.0, 7.0]
    finally:
        for bus in (rx, keeps, wall):
            bus.shutdown()


def test_no_code_reads_a_messages_is_rx_flag() -> None:
    """A local sender's frames on a vcan (every simulator process, ``cansend``) arrive with
    ``is_rx`` false (the socketcan tier shows it on a kernel bus), so the gateway takes frames
    whatever the flag says: no code of it reads the flag."""
    readers = []
    for path in [*(REPO / "gateway").rglob("*.py"), *(REPO / "drivers").rglob("*.py")]:
        for node in ast.walk(ast.parse(path.read_text())):
            # (A log entry's is_rx is the direction token of a candump line, not the flag.)
            if (isinstance(node, ast.Attribute) and node.attr == "is_rx"
                    and isinstance(node.ctx, ast.Load)
                    and not (isinstance(node.value, ast.Name) and node.value.id == "entry")):
                readers.append(f"{path.relative_to(REPO)}:{node.lineno}")
    assert readers == []
