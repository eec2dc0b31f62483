"""The bus-load budget's arithmetic (:mod:`gateway.drive.traffic`)."""

from __future__ import annotations

import pytest

from gateway.core.types import Frame
from gateway.drive.traffic import BusBudget, Sender, Stream, frame_streams


def _stream(per_s: float, sender: Sender = Sender.CONTROLLERS, dlc: int = 8,
            extended: bool = False, remote: bool = False) -> Stream:
    return Stream("M", sender, per_s, dlc, extended, "test", remote)


def test_four_dji_escs_load_a_1_mbit_bus_55_5_to_67_5_percent() -> None:
    # One command frame and four feedback frames a millisecond, 8 bytes, 11-bit: 111 bits
    # nominal, 135 with the most stuff bits (Davis et al. 2007), 5000 frames/s at 1 Mbit/s.
    budget = BusBudget((_stream(1000.0, Sender.GATEWAY), _stream(4000.0)), 1_000_000)
    assert budget.load() == pytest.approx(55.5)
    assert budget.load(worst_case=True) == pytest.approx(67.5)
    assert budget.load(sender=Sender.GATEWAY) == pytest.approx(11.1)
    assert budget.per_s(Sender.CONTROLLERS) == 4000.0
    assert not budget.full()
    assert not budget.high()


def test_stream_bits_by_shape() -> None:
    assert _stream(1.0).bits_per_s() == 111
    assert _stream(1.0, extended=True).bits_per_s(worst_case=True) == 160
    assert _stream(1.0, dlc=4, extended=True).bits_per_s() == 99
    # A remote frame carries no data, whatever length it asks for.
    assert _stream(1.0, dlc=8, remote=True).bits_per_s() == 47


def test_thresholds() -> None:
    # 70 % worst case is the edge of the warning; 100 % nominal of the refusal.
    per_s_at_70 = 0.70 * 500_000 / 135
    assert not BusBudget((_stream(per_s_at_70 * 0.999),), 500_000).high()
    assert BusBudget((_stream(per_s_at_70 * 1.001),), 500_000).high()
    per_s_full = 500_000 / 111
    assert not BusBudget((_stream(per_s_full * 0.999),), 500_000).full()
    assert BusBudget((_stream(per_s_full),), 500_000).full()


def test_frame_streams_group_by_message_and_shape_in_order() -> None:
    frames = [Frame(0x2D, bytes(8)), Frame(0x4D, bytes(8)), Frame(0x80),
              Frame(0x12345678, bytes(4), is_extended_id=True), Frame(0x29, is_remote_frame=True)]
    names = {0x2D: "Set_Input_Vel", 0x4D: "Set_Input_Vel", 0x80: "SYNC"}
    streams = frame_streams(frames, 200.0, lambda i, ext: None if ext else names.get(i),
                            Sender.GATEWAY, "every cycle")
    assert [(s.name, s.per_s, s.dlc, s.extended, s.remote) for s in streams] == [
        ("Set_Input_Vel", 400.0, 8, False, False), ("SYNC", 200.0, 0, False, False),
        ("0x12345678", 200.0, 4, True, False), ("0x029", 200.0, 0, False, True)]


def test_lines_and_brief_name_every_stream_and_the_unknown() -> None:
    budget = BusBudget(
        (Stream("Set_Input_Vel", Sender.GATEWAY, 800.0, 8, False, "every cycle"),
         Stream("Heartbeat", Sender.CONTROLLERS, 40.0, 8, False, "100 ms each")),
        500_000, ("STATUS of 1 VESC(s) whose status_rate_hz is not stated",))
    assert budget.lines() == [
        "gateway       800.0/s  Set_Input_Vel (8 B): every cycle",
        "controllers    40.0/s  Heartbeat (8 B): 100 ms each",
        "not counted: STATUS of 1 VESC(s) whose status_rate_hz is not stated"]
    assert budget.brief() == "800/s Set_Input_Vel, 40/s Heartbeat"
    assert budget.summary() == ("18.6-22.7 % of 500 kbit/s (840 frames/s: gateway 800, "
                                "controllers 40)")
