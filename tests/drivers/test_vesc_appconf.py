"""COMM_GET_APPCONF over CAN, the pure half (drivers/vesc/appconf.py, drivers/vesc/sim_appconf.py).

Golden bytes built by hand from the firmware's rules (https://github.com/vedderb/bldc, read at
``b9d287b3`` and the tag ``6.00``): ``comm/comm_can.c`` (``decode_msg``,
``CAN_PACKET_PROCESS_SHORT_BUFFER``; ``comm_can_send_buffer``), ``datatypes.h``
(``CAN_PACKET_FILL_RX_BUFFER`` 5, ``_LONG`` 6, ``PROCESS_RX_BUFFER`` 7, ``PROCESS_SHORT_BUFFER``
8; ``COMM_GET_APPCONF`` 17), ``util/crc.c`` (``crc16``: CRC-16/XMODEM, whose check value for
"123456789" is 0x31C3), ``confgenerator.c`` (``confgenerator_serialize_appconf``) and
``confgenerator.h`` at 6.00 (``APPCONF_SIGNATURE`` 486554156 = 0x1D003A2C).
"""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.vesc.appconf import (
    HOST_ID,
    AppconfTimeout,
    LayoutError,
    Reassembly,
    crc16,
    make_get_appconf,
    parse_appconf,
)
from drivers.vesc.scan import PINGER_ID
from drivers.vesc.sim_appconf import LENGTH_6_00, SIGNATURE_6_00, send_buffer, serialize_appconf
from gateway.core.errors import DecodeError
from gateway.core.types import Frame


def ext(arbitration_id: int, hex_data: str) -> Frame:
    return Frame(arbitration_id, bytes.fromhex(hex_data), True)


def reassemble(frames: list[Frame]) -> tuple[int, int, bytes]:
    rx, out = Reassembly(), []
    for f in frames:
        reply = rx.feed(f)
        if reply is not None:
            out.append((reply.sender_id, reply.send_mode, reply.payload))
    (whole,) = out
    return whole


def test_the_request_is_a_short_buffer_from_the_gateways_id() -> None:
    # (8 << 8) | 23 = 0x817; [sender 254, send mode 0 (process, reply), COMM_GET_APPCONF 17].
    assert make_get_appconf(23) == ext(0x817, "FE0011")
    assert HOST_ID == PINGER_ID == 254  # the ID the scan pings as
    with pytest.raises(ValueError, match=r"VESC ID: expected 0\.\.255, got 256"):
        make_get_appconf(256)


def test_crc16_is_the_firmwares_xmodem() -> None:
    assert crc16(b"123456789") == 0x31C3
    assert crc16(b"") == 0


def test_a_reply_of_six_bytes_or_less_is_one_short_buffer() -> None:
    # len <= 6: [the VESC's ID, send mode 1 (a reply), the bytes] to (8 << 8) | 254.
    frames = send_buffer(254, 23, bytes.fromhex("110102"))
    assert frames == [ext(0x8FE, "1701110102")]
    assert reassemble(frames) == (23, 1, bytes.fromhex("110102"))


def test_a_longer_reply_is_fill_frames_then_the_end_with_length_and_crc() -> None:
    data = bytes(range(1, 11))  # 10 bytes: offsets 0 and 7, then PROCESS_RX_BUFFER
    crc = crc16(data)
    assert send_buffer(254, 23, data) == [
        ext(0x5FE, "00" "01020304050607"),
        ext(0x6FE - 0x100, "07" "08090A"),
        ext(0x7FE, f"17" f"01" f"000A" f"{crc:04X}"),
    ]
    assert reassemble(send_buffer(254, 23, data)) == (23, 1, data)


def test_the_6_00_appconf_reply_frame_by_frame() -> None:
    conf = serialize_appconf(23, 1000)
    assert len(conf) == LENGTH_6_00 == 493
    # signature 0x1D003A2C, controller_id 0x17, timeout_msec 1000 = 0x000003E8,
    # timeout_brake_current 0.0 (float32_auto: four zero bytes), can_status_rate_1 50 = 0x0032.
    assert conf[:16].hex().upper() == "1D003A2C" "17" "000003E8" "00000000" "0032" "00"
    reply = bytes((17,)) + conf  # 494 bytes
    frames = send_buffer(254, 23, reply)
    fill = [f for f in frames if f.arbitration_id == 0x5FE]
    long = [f for f in frames if f.arbitration_id == 0x6FE]
    # FILL_RX_BUFFER for the offsets 0, 7, ... 252 (the loop stops past 255), then
    # FILL_RX_BUFFER_LONG from 259 = 0x0103, six bytes each, the last at 493 = 0x01ED (1 byte).
    assert [f.data[0] for f in fill] == list(range(0, 253, 7))
    # [offset, 7 bytes]: the packet 0x11, the signature, controller_id, timeout_msec's first.
    assert fill[0] == ext(0x5FE, "00" "11" "1D003A2C" "17" "00")
    assert fill[1] == ext(0x5FE, "07" "0003E8" "00000000")
    assert long[0].data[:2] == bytes.fromhex("0103") and long[-1].data == bytes.fromhex("01ED00")
    assert len(fill) + len(long) == 37 + 40
    assert frames[-1] == ext(0x7FE, f"1701" "01EE" f"{crc16(reply):04X}")
    assert reassemble(frames) == (23, 1, reply)
    assert parse_appconf(reply, 23) == AppconfTimeout(SIGNATURE_6_00, 23, 1000)


@given(
    st.binary(min_size=1, max_size=512),
    st.integers(0, 255),
    st.integers(0, 254),
)
def test_any_buffer_survives_the_round_trip(data: bytes, to_id: int, sender: int) -> None:
    frames = send_buffer(to_id, sender, data)
    assert all(f.is_extended_id and f.arbitration_id & 0xFF == to_id for f in frames)
    assert all(1 <= len(f.data) <= 8 for f in frames)
    assert reassemble(frames) == (sender, 1, data)


@given(st.integers(0, 254), st.integers(0, 2**32 - 1), st.integers(0, 2**32 - 1),
       st.integers(10, 600))
def test_the_timeout_survives_the_round_trip(node: int, ms: int, signature: int,
                                             length: int) -> None:
    reply = bytes((17,)) + serialize_appconf(node, ms, signature=signature, length=length)
    _, _, payload = reassemble(send_buffer(HOST_ID, node, reply))
    assert parse_appconf(payload, node) == AppconfTimeout(signature, node, ms)


def test_a_wrong_crc_is_a_decode_error_naming_both() -> None:
    frames = send_buffer(254, 23, bytes(range(20)))
    good = crc16(bytes(range(20)))
    end = frames[-1]
    frames[-1] = Frame(end.arbitration_id, bytes(end.data[:4]) + (good ^ 1).to_bytes(2, "big"),
                       True)
    with pytest.raises(DecodeError, match=(
            f"PROCESS_RX_BUFFER: expected crc16 0x{good:04X} of the 20 bytes received, got "
            f"0x{good ^ 1:04X}")):
        reassemble(frames)


def test_a_lost_frame_or_a_wrong_length_is_a_decode_error() -> None:
    frames = send_buffer(254, 23, bytes(range(20)))
    rx = Reassembly()
    rx.feed(frames[0])
    with pytest.raises(DecodeError, match="expected offset 7 \\(the bytes so far\\), got 14"):
        rx.feed(frames[2])
    rx = Reassembly()
    rx.feed(frames[0])
    with pytest.raises(DecodeError, match="expected the length of the 7 bytes received, got 20"):
        rx.feed(frames[-1])
    with pytest.raises(DecodeError, match="expected a data frame of at least 6 bytes, got 5"):
        rx.feed(ext(0x7FE, "1701001400"))


def test_the_reply_must_be_appconf_long_enough_and_name_the_vesc() -> None:
    reply = bytes((17,)) + serialize_appconf(23, 1000)
    with pytest.raises(DecodeError, match=r"expected a COMM_GET_APPCONF reply \(packet 17\), "
                                          r"got packet 0"):
        parse_appconf(b"\x00" + reply[1:], 23)
    with pytest.raises(DecodeError, match=r"of at least 10 bytes .*got 9"):
        parse_appconf(reply[:9], 23)
    with pytest.raises(LayoutError, match=(
            r"cannot read the timeout: the reply's layout is not the one expected \(byte 5, "
            r"controller_id, is 23, expected the VESC's ID 24; signature 486554156\)")):
        parse_appconf(reply, 24)
