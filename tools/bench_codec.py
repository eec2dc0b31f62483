"""Benchmark: wheelgate's hand-written codecs against cantools on the same messages.

Run from the repository with the project's environment::

    .venv/bin/python tools/bench_codec.py [--number N]

Cases: ODrive Set_Input_Vel encode and Get_Encoder_Estimates decode against the official
0.5.6 DBC (``tests/data/odrive-cansimple-0.5.6.dbc``); the VESC and DJI velocity command and
feedback codecs against a cantools database built in code for the same layout.  Before timing,
every pair is checked to produce the same payload (encode) or the same values (decode).

Method: each callable runs ``N`` times in a plain ``for`` loop timed with
``time.perf_counter_ns``; that is one round.  Five rounds give five per-call times (round time
/ N) minus the harness cost (the same loop calling a no-op); the table shows the best and the
median of the five.  The ratio is cantools / ours on the medians.  "ours" is the full codec
call: arbitration ID, range checks, payload and the frozen ``Frame`` (encode) or the ID
dispatch, checks and frozen message dataclass (decode); cantools' ``Message.encode`` returns
only the payload and ``Message.decode`` only a dict, so a second ODrive row times our payload
packing alone (``Layout.pack`` with the same float32 range check that cantools' strict encode
does).
"""

from __future__ import annotations

import argparse
import logging
import math
import platform
import statistics
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cantools
from cantools.database.can import Database, Message, Signal
from cantools.database.conversion import BaseConversion

import drivers.dji.codec as dji
import drivers.vesc.codec as vesc
from drivers.odrive.codec import OdriveCodec
from drivers.odrive.messages import FLOAT32_MAX, SET_INPUT_VEL, EncoderEstimates
from gateway.core.types import Frame

if TYPE_CHECKING:
    from collections.abc import Callable

ROUNDS = 5
DBC_PATH = Path(__file__).resolve().parent.parent / "tests" / "data" / "odrive-cansimple-0.5.6.dbc"


@dataclass(frozen=True)
class Case:
    """One message, coded by us and by cantools."""

    label: str
    ours: Callable[[], object]
    theirs: Callable[[], object]


def _noop() -> None:
    return None


def time_per_call_us(
    fn: Callable[[], object], number: int, overhead_us: float = 0.0
) -> list[float]:
    """Per-call time in µs of each of :data:`ROUNDS` rounds of ``number`` calls."""
    out = []
    for _ in range(ROUNDS):
        start = time.perf_counter_ns()
        for _ in range(number):
            fn()
        out.append((time.perf_counter_ns() - start) / number / 1000.0 - overhead_us)
    return out


def _signal(name: str, start: int, length: int, signed: bool, scale: float = 1.0) -> Any:
    conversion = BaseConversion.factory(scale=scale, offset=0.0)
    return Signal(name, start, length, "big_endian", signed, conversion=conversion)


def _database(frame_id: int, name: str, signals: list[Any], extended: bool) -> Any:
    length = 8 if len(signals) > 1 else 4
    db = Database([Message(frame_id, name, length, signals, is_extended_frame=extended)])
    db.refresh()
    return db.get_message_by_name(name)


def odrive_cases() -> list[Case]:
    """Set_Input_Vel encode and Get_Encoder_Estimates decode against the official DBC."""
    logging.getLogger("cantools").setLevel(logging.ERROR)  # "Overwriting message" warnings
    db: Any = cantools.database.load_file(str(DBC_PATH), frame_id_mask=0x1F)
    codec = OdriveCodec()
    vel_msg = db.get_message_by_frame_id(0x06D)
    est_msg = db.get_message_by_frame_id(0x069)
    values = {"Input_Vel": 10.0, "Input_Torque_FF": 0.0}
    est = codec.make_encoder_estimates(3, 12.5, -2.25)

    def pack_checked() -> bytes:
        if not (-FLOAT32_MAX <= 10.0 <= FLOAT32_MAX and -FLOAT32_MAX <= 0.0 <= FLOAT32_MAX):
            raise ValueError("out of range")
        return SET_INPUT_VEL.pack(10.0, 0.0)

    if codec.make_set_input_vel(3, 10.0).data != vel_msg.encode(values):
        raise SystemExit("ODrive Set_Input_Vel: payloads differ")
    decoded = codec.decode(est)
    if not isinstance(decoded, EncoderEstimates) or est_msg.decode(est.data) != {
        "Pos_Estimate": decoded.pos_turns,
        "Vel_Estimate": decoded.vel_turns_s,
    }:
        raise SystemExit("ODrive Get_Encoder_Estimates: values differ")
    return [
        Case(
            "ODrive Set_Input_Vel encode (Frame)",
            lambda: codec.make_set_input_vel(3, 10.0),
            lambda: vel_msg.encode(values),
        ),
        Case("ODrive Set_Input_Vel encode (payload)", pack_checked, lambda: vel_msg.encode(values)),
        Case(
            "ODrive Get_Encoder_Estimates decode",
            lambda: codec.decode(est),
            lambda: est_msg.decode(est.data),
        ),
    ]


def vesc_cases() -> list[Case]:
    """SET_RPM encode and STATUS decode against a cantools database built in code."""
    rpm = _database(0x317, "SET_RPM", [_signal("ERPM", 7, 32, True)], extended=True)
    status = _database(
        0x917,
        "STATUS",
        [
            _signal("ERPM", 7, 32, True),
            _signal("Current", 39, 16, True, 0.1),
            _signal("Duty", 55, 16, True, 0.001),
        ],
        extended=True,
    )
    frame = Frame(0x917, bytes.fromhex("000002BC007B01F4"), is_extended_id=True)
    if vesc.make_set_rpm(23, 700.0).data != rpm.encode({"ERPM": 700}):
        raise SystemExit("VESC SET_RPM: payloads differ")
    ref = status.decode(frame.data)
    got = vesc.decode(frame)
    if (not isinstance(got, vesc.VescStatus) or not math.isclose(ref["Current"], got.current_a)
            or ref["ERPM"] != got.erpm):
        raise SystemExit("VESC STATUS: values differ")
    return [
        Case(
            "VESC SET_RPM encode",
            lambda: vesc.make_set_rpm(23, 700.0),
            lambda: rpm.encode({"ERPM": 700}),
        ),
        Case("VESC STATUS decode", lambda: vesc.decode(frame), lambda: status.decode(frame.data)),
    ]


def dji_cases() -> list[Case]:
    """0x200 current command encode and 0x201 feedback decode, cantools built in code."""
    names = [f"ESC{k}" for k in range(1, 5)]
    signals = [_signal(n, 7 + 16 * k, 16, True) for k, n in enumerate(names)]
    command = _database(0x200, "CMD", signals, extended=False)
    feedback = _database(
        0x201,
        "FEEDBACK",
        [
            _signal("Angle", 7, 16, False),
            _signal("Speed", 23, 16, True),
            _signal("Current", 39, 16, True),
            _signal("Temperature", 55, 8, False),
        ],
        extended=False,
    )
    raw = [4000, -4000, 0, 1000, 0, 0, 0, 0]
    values = {f"ESC{k}": raw[k - 1] for k in range(1, 5)}
    frame = Frame(0x201, bytes.fromhex("1FFF05DCFF382300"))
    if dji.encode_command(raw, (0,))[0].data != command.encode(values):
        raise SystemExit("DJI 0x200: payloads differ")
    if dji.decode_feedback(frame) is None or feedback.decode(frame.data)["Angle"] != 8191:
        raise SystemExit("DJI feedback: values differ")
    return [
        Case(
            "DJI 0x200 command encode (4 ESCs)",
            lambda: dji.encode_command(raw, (0,)),
            lambda: command.encode(values),
        ),
        Case(
            "DJI 0x201 feedback decode",
            lambda: dji.decode_feedback(frame),
            lambda: feedback.decode(frame.data),
        ),
    ]


def main() -> None:
    """Run every case and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--number", type=int, default=20_000, help="calls per round")
    number = parser.parse_args().number
    cases = odrive_cases() + vesc_cases() + dji_cases()
    overhead = statistics.median(time_per_call_us(_noop, number))
    frame_us = statistics.median(time_per_call_us(lambda: Frame(0x6D, b"12345678"), number))
    print(
        f"Python {platform.python_version()}, cantools {cantools.__version__}; "
        f"{ROUNDS} rounds x {number} calls, time.perf_counter_ns; harness overhead "
        f"{overhead:.3f} us/call subtracted; ratio = cantools / ours (medians)."
    )
    print(f"{'case':40} {'ours best/median us':>21} {'cantools best/median us':>25} {'ratio':>6}")
    for case in cases:
        ours = time_per_call_us(case.ours, number, overhead)
        theirs = time_per_call_us(case.theirs, number, overhead)
        ratio = statistics.median(theirs) / statistics.median(ours)
        print(
            f"{case.label:40} {min(ours):9.3f} / {statistics.median(ours):9.3f} "
            f"{min(theirs):11.3f} / {statistics.median(theirs):11.3f} {ratio:6.1f}x"
        )
    frame_us -= overhead
    print(f"(for scale: constructing one frozen gateway.core.types.Frame costs {frame_us:.3f} us)")


if __name__ == "__main__":
    main()
