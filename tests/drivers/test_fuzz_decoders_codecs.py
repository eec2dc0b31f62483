"""Fuzzing of the pure codecs, the candump reader and the device simulators.  The rules checked:

* the pure codecs' decoders return a message or ``None`` or raise ``DecodeError``, nothing else;
* the device simulators (``--sim``) take any frame without raising;
* the candump log reader raises ``CandumpError`` only, and accepts only sane IDs and stamps.
"""

from __future__ import annotations

import functools
import math
from typing import TYPE_CHECKING, TypeAlias

import pytest
from hypothesis import assume, example, given
from hypothesis import strategies as st

from drivers.cia402 import Cia402Codec, PdoLayout
from drivers.cia402.sdo import parse_sdo_request, parse_sdo_response
from drivers.dbc import DbcDriver
from drivers.dji.codec import decode_command as dji_decode_command
from drivers.dji.codec import decode_feedback as dji_decode_feedback
from drivers.odrive import Firmware, OdriveCodec
from drivers.odrive.commands import decode_command
from drivers.vesc.codec import decode as vesc_decode
from drivers.vesc.codec import decode_command as vesc_decode_command
from gateway.core.errors import DecodeError
from gateway.core.types import Frame
from gateway.sim.registry import simulator_for
from gateway.wire.can import CanIds, WgCodec
from gateway.wire.candump import CandumpError, parse_line
from tests.drivers.fuzz_decoder_helpers import (
    ALL_CASES,
    DBC_FLOAT,
    FUZZ,
    Own,
    _fresh,
    _prototype,
    frames,
    make_driver,
    own_feedback,
)

if TYPE_CHECKING:
    from collections.abc import Callable

    from gateway.sim.device import DeviceSimulator


def make_simulators(case: str) -> list[DeviceSimulator]:
    """Fresh device simulators for every motor of ``case`` (DBC ones copied, as above)."""
    proto = _prototype(case)
    if isinstance(proto, DbcDriver):
        return _fresh(_prototype_sims(case), proto.motors)
    return [simulator_for(m) for m in proto.motors]


@functools.cache
def _prototype_sims(case: str) -> list[DeviceSimulator]:
    drv = _prototype(case)
    return [simulator_for(m) for m in drv.motors]


# ------------------------------------------------------------------------------- codecs


Decoders: TypeAlias = "list[Callable[[Frame], object]]"


def _wg(ext: bool) -> Callable[[Frame], object]:
    base = 0x18FF0000 if ext else 0x100
    ids = CanIds(base, base + 1, base + 2, base + 3, base + 4, extended=ext)
    return WgCodec(ids).decode


def _dbc_decoders(case: str) -> Decoders:
    drv = make_driver(case)
    assert isinstance(drv, DbcDriver)
    return [drv.codec.decode, drv.codec.decode_request]


CIA402 = Cia402Codec({1: PdoLayout(), 5: PdoLayout(rpdo=1, tpdo_position=1, tpdo_velocity=2)})

def _odrive_decoders(fw: Firmware, ext: bool) -> Decoders:
    codec = OdriveCodec(fw, ext)
    return [codec.decode, functools.partial(decode_command, codec)]


def _aims(ids: list[int], ext: bool = False) -> list[Own]:
    return [Own(i, ext, frozenset({8})) for i in ids]


#: Codec name -> (its decoders, which may return None; IDs to aim at).
CODECS: dict[str, tuple[Callable[[], Decoders], list[Own]]] = {
    **{
        f"odrive-{fw.value}{'-ext' if ext else ''}": (
            functools.partial(_odrive_decoders, fw, ext),
            _aims([n << 5 | c for n in (0, 1, 0x3F) for c in range(32)], ext),
        )
        for fw in Firmware
        for ext in (False, True)
    },
    "vesc": (
        lambda: [vesc_decode, vesc_decode_command],
        _aims([p << 8 | n for p in range(64) for n in (0, 10, 255)], True),
    ),
    "cia402": (
        lambda: [CIA402.decode],
        _aims([b + n for b in range(0x80, 0x800, 0x80) for n in (1, 5, 9)]),
    ),
    "dji": (lambda: [dji_decode_feedback, dji_decode_command], _aims(list(range(0x1FE, 0x20A)))),
    "dbc": (functools.partial(_dbc_decoders, "dbc"), _aims(list(range(0x180, 0x290)))),
    DBC_FLOAT: (functools.partial(_dbc_decoders, DBC_FLOAT), _aims(list(range(0x60, 0x80)))),
    "wgproto": (
        lambda: [_wg(False), _wg(True)],
        _aims([0x100 + k for k in range(5)]) + _aims([0x18FF0000 + k for k in range(5)], True),
    ),
}


@pytest.mark.parametrize("name", list(CODECS))
@FUZZ
@given(data=st.data())
def test_codec_decoders_return_none_or_raise_only_decode_error(
    name: str, data: st.DataObject
) -> None:
    make, aims = CODECS[name]
    decoders = make()
    for frame in data.draw(st.lists(frames(aims), min_size=1, max_size=20)):
        for decode in decoders:
            try:
                decode(frame)
            except DecodeError as err:
                assert str(err)


@FUZZ
@given(data=st.data())
def test_sdo_parsers_raise_only_decode_error(data: st.DataObject) -> None:
    aims = [Own(b + n, False, frozenset({8})) for b in (0x580, 0x600) for n in (0, 1, 127, 128)]
    for frame in data.draw(st.lists(frames(aims), min_size=1, max_size=20)):
        for parse in (parse_sdo_response, parse_sdo_request):
            try:
                parse(frame)
            except DecodeError as err:
                assert str(err)


FINITE_STAMPS = ["(1.5)", "(0)", "(1700000000.123456)", "(-1.5)", "(1.5.2)", "()", "1.5", "(x)"]
NON_FINITE_STAMPS = ["(nan)", "(inf)", "(-inf)", "(1e999)", "(NaN)", "(Infinity)"]


def candump_lines(stamps: list[str]) -> st.SearchStrategy[str]:
    """Random text, and lines shaped like ``(stamp) channel ID#DATA [R|T]`` with awkward
    parts: 2- to 9-digit IDs, odd-length and long data, remote frames R0..R9, CAN FD ``##``."""
    ident = st.sampled_from(["123", "7FF", "800", "000", "1FFFFFFF", "20000000", "12", "1234",
                             "12345678", "xyz", ""])
    data = st.binary(max_size=10).map(lambda b: b.hex().upper()) | st.sampled_from(
        ["R", "R0", "R8", "R9", "R-1", "0", "ZZ", "#0", "#1122", " 11"]
    )
    shaped = st.builds(
        "{} {} {}#{}{}".format,
        st.sampled_from(stamps),
        st.sampled_from(["can0", "vcan0", "x" * 40]),
        ident,
        data,
        st.sampled_from(["", " R", " T", " X", " R R"]),
    )
    return st.text(max_size=80) | shaped


def _sign_or_prefix_in_id(line: str) -> bool:
    """IDs like -01, +7F, 0x7, 1_2 (refused, tested on their own below)."""
    parts = line.split()
    ident = parts[2].partition("#")[0] if len(parts) > 2 else ""
    return any(c in ident for c in "+-_xX")


@FUZZ
@given(line=candump_lines(FINITE_STAMPS))
def test_candump_lines_raise_only_candump_error(line: str) -> None:
    assume(not _sign_or_prefix_in_id(line))
    try:
        entry = parse_line(line, 7)
    except CandumpError as err:
        assert str(err).startswith("line 7: ")
    else:
        frame = entry.frame
        assert len(frame.data) <= 8
        assert 0 <= frame.arbitration_id <= (0x1FFFFFFF if frame.is_extended_id else 0x7FF)


@FUZZ
@given(line=candump_lines(NON_FINITE_STAMPS))
@example(line="(inf) can0 069#0000000000000000")
@example(line="(nan) can0 069#0000000000000000")
def test_candump_time_stamps_must_be_finite(line: str) -> None:
    try:
        entry = parse_line(line, 7)
    except CandumpError:
        return
    assert math.isfinite(entry.timestamp_s), line


@pytest.mark.parametrize("ident", ["-01", "+7F", "0x7", "1_2", "-0000001", "0x00007F"])
def test_candump_ids_are_plain_hexadecimal(ident: str) -> None:
    try:
        entry = parse_line(f"(1.5) can0 {ident}#00", 7)
    except CandumpError as err:
        assert "hexadecimal ID" in str(err)
    else:
        raise AssertionError(f"ID {ident!r} read as {entry.frame.arbitration_id}")


# ------------------------------------------------------------------------------- simulators


@pytest.mark.parametrize("case", ALL_CASES)
@FUZZ
@given(data=st.data())
def test_device_simulators_take_any_frame(case: str, data: st.DataObject) -> None:
    drv = make_driver(case)
    sims = make_simulators(case)
    own = own_feedback(drv)
    # Aim at what the simulators read: the host's commands (the driver's enable frames and a
    # command) as well as the feedback IDs.
    host = drv.enable(0.0) + drv.command([0.0] * len(drv.motors), 0.0)
    aims = own + [Own(f.arbitration_id, f.is_extended_id, frozenset({f.dlc})) for f in host]
    t = 0.0
    for frame in data.draw(st.lists(frames(aims), max_size=25)):
        for sim in sims:
            out = sim.handle(frame, t) + sim.tick(t)
            assert all(isinstance(f, Frame) for f in out)
        t += 0.001
