"""``diagnostic_msgs/msg/DiagnosticArray``'s codec: byte for byte against pycdr2 (the independent
encoder of cyclonedds-python, the message declared here field for field as the ``.msg`` files
declare it; ``byte`` is IDL's ``octet``, one byte as ``uint8``), for every padding and for any
message hypothesis draws; and every malformed payload a precise error."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from gateway.core.errors import DecodeError, EncodeError
from gateway.wire.ros2 import (
    DiagnosticArray,
    DiagnosticLevel,
    DiagnosticStatus,
    Header,
    KeyValue,
    Time,
    decode_diagnostic_array,
    encode_diagnostic_array,
)

pytest.importorskip("pycdr2", reason="pycdr2 (pip install pycdr2) is the independent CDR "
                                     "encoder these tests compare with")

from tests.wire.test_ros2_cdr_pycdr2 import HEADERS, NAMES, CHeader, T, c_header, cdr, idl_struct

CKeyValue = idl_struct("diagnostic_msgs::msg::dds_::KeyValue_", key=str, value=str)
CDiagnosticStatus = idl_struct("diagnostic_msgs::msg::dds_::DiagnosticStatus_", level=T.uint8,
                               name=str, message=str, hardware_id=str,
                               values=T.sequence[CKeyValue])
CDiagnosticArray = idl_struct("diagnostic_msgs::msg::dds_::DiagnosticArray_", header=CHeader,
                              status=T.sequence[CDiagnosticStatus])


def c_array(m: DiagnosticArray) -> Any:
    return CDiagnosticArray(c_header(m.header), [
        CDiagnosticStatus(int(s.level), s.name, s.message, s.hardware_id,
                          [CKeyValue(v.key, v.value) for v in s.values])
        for s in m.status])


STATUSES = st.builds(DiagnosticStatus, st.sampled_from(DiagnosticLevel), NAMES, NAMES, NAMES,
                     st.lists(st.builds(KeyValue, NAMES, NAMES), max_size=4).map(tuple))
ARRAYS = st.builds(DiagnosticArray, HEADERS, st.lists(STATUSES, max_size=4).map(tuple))

EXAMPLE = DiagnosticArray(Header(Time(1_700_000_000, 250_000_000), ""), (
    DiagnosticStatus(DiagnosticLevel.OK, "wheelgate: gateway", "running", "robot1",
                     (KeyValue("state", "running"), KeyValue("reason", ""))),
    DiagnosticStatus(DiagnosticLevel.ERROR, "wheelgate: motor rl", "fault", "can0 node 3"),
))


@pytest.mark.parametrize("name", ["", "a", "ab", "abc", "abcd", "ünï"])
def test_diagnostic_array_matches_pycdr2_for_every_padding(name: str) -> None:
    """The level byte lands at every offset modulo 4 before the aligned string length."""
    message = DiagnosticArray(Header(Time(1, 2), name), (
        DiagnosticStatus(DiagnosticLevel.WARN, name, name, name, (KeyValue(name, name),)),
        DiagnosticStatus(DiagnosticLevel.STALE, "x", "", name),
    ))
    expected = cdr(c_array(message))
    assert encode_diagnostic_array(message) == expected
    assert decode_diagnostic_array(expected) == message


def test_an_empty_report_and_the_example() -> None:
    empty = DiagnosticArray(Header())
    assert encode_diagnostic_array(empty) == cdr(c_array(empty))
    assert decode_diagnostic_array(encode_diagnostic_array(EXAMPLE)) == EXAMPLE


@given(ARRAYS)
def test_any_diagnostic_array_matches_pycdr2(message: DiagnosticArray) -> None:
    expected = cdr(c_array(message))
    assert encode_diagnostic_array(message) == expected
    assert decode_diagnostic_array(expected) == message


def test_a_level_outside_the_four_is_refused_by_name() -> None:
    bad = cdr(CDiagnosticArray(c_header(Header()), [CDiagnosticStatus(4, "m", "", "", [])]))
    with pytest.raises(DecodeError, match=r"diagnostic_msgs/msg/DiagnosticArray: expected 0 "
                       r"\(OK\), 1 \(WARN\), 2 \(ERROR\) or 3 \(STALE\) for status\[0\]\.level, "
                       r"got 4"):
        decode_diagnostic_array(bad)


@given(ARRAYS, st.data())
def test_a_payload_cut_short_or_lengthened_is_a_decode_error(message: DiagnosticArray,
                                                             data: st.DataObject) -> None:
    payload = encode_diagnostic_array(message)
    cut = data.draw(st.integers(0, len(payload) - 1))
    with pytest.raises(DecodeError, match=r"^diagnostic_msgs/msg/DiagnosticArray: expected"):
        decode_diagnostic_array(payload[:cut])
    with pytest.raises(DecodeError, match=r"^diagnostic_msgs/msg/DiagnosticArray: expected"):
        decode_diagnostic_array(payload + b"\x01" * 9)


@pytest.mark.parametrize(("message", "where"), [
    (DiagnosticArray(Header(), (DiagnosticStatus(level=1),)),  # type: ignore[arg-type]
     r"a DiagnosticStatus with a DiagnosticLevel and a sequence of KeyValue for status\[0\]"),
    (DiagnosticArray(Header(), (DiagnosticStatus(values=(("k", "v"),)),)),  # type: ignore[arg-type]
     r"a KeyValue for status\[0\]\.values\[0\], got \('k', 'v'\)"),
    (DiagnosticArray(Header(), (DiagnosticStatus(name="a\0b"),)),
     r"no NUL in status\[0\]\.name"),
    (DiagnosticArray(Header(), (DiagnosticStatus(values=(KeyValue("k", 3),),),)),  # type: ignore[arg-type]
     r"a str for status\[0\]\.values\[0\]\.value, got 3"),
    ("not a message", r"a DiagnosticArray with a sequence of DiagnosticStatus, got 'not a "),
])
def test_what_cannot_go_on_the_wire_is_named(message: Any, where: str) -> None:
    with pytest.raises(EncodeError, match=rf"^diagnostic_msgs/msg/DiagnosticArray: expected "
                       rf"{where}"):
        encode_diagnostic_array(message)
