"""The live view's ``/diagnostics`` (:mod:`gateway.runtime.liveview`): the gateway's status as ROS
2's own ``diagnostic_msgs/msg/DiagnosticArray``, CDR under its complete ``ros2msg`` definition,
as the Foxglove app's Diagnostics panels take it; read back from the recording by our decoder and
by the MCAP maintainers' ROS 2 decoder (``mcap-ros2-support``), which parses the schema itself.
The daemon's schedule of those reports is tested in ``test_diagnostics.py``."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import pytest

from gateway.core.bridge_settings import FoxgloveSettings
from gateway.runtime.diagnostics import diagnostic_array
from gateway.runtime.liveview import LiveView
from gateway.wire.ros2 import decode_diagnostic_array
from tests.wire.status_samples import sample_status

if TYPE_CHECKING:
    from pathlib import Path

EXTRA = "pip install 'wheelgate[foxglove]'"
pytest.importorskip("foxglove", reason=f"foxglove-sdk not installed: {EXTRA}")
make_reader = pytest.importorskip("mcap.reader", reason=f"mcap not installed: {EXTRA}").make_reader

HARDWARE = {"left": "odrive node 1 on socketcan:can0", "right": "odrive node 2 on socketcan:can0"}
WAIT_S = 5.0


def wait_for(view: LiveView, what: str, **counts: int) -> None:
    deadline = time.monotonic() + WAIT_S
    while any(getattr(view.stats(), k) < v for k, v in counts.items()):
        assert time.monotonic() < deadline, f"timed out waiting for {what}: {view.stats()}"
        time.sleep(0.001)


def diagnostics_in(path: Path, decoders: list[Any] | None = None) -> list[tuple[Any, ...]]:
    """``(schema, channel, message, decoded)`` of every ``/diagnostics`` message (``decoded``
    only with ``decoders``)."""
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=decoders or [])
        if decoders:
            return [(s, c, m, d) for s, c, m, d in reader.iter_decoded_messages(
                topics=["/diagnostics"], log_time_order=True)]
        return [(s, c, m, None) for s, c, m in reader.iter_messages(
            topics=["/diagnostics"], log_time_order=True)]


def record_reports(path: Path, *reports: object) -> LiveView:
    view = LiveView(FoxgloveSettings(), "rover", ("left", "right"), record_mcap=str(path),
                    serve=False, hardware=HARDWARE)
    with view:
        for count, report in enumerate(reports, start=1):
            view.mailbox.post(report=report)  # type: ignore[arg-type]
            deadline = time.monotonic() + WAIT_S
            while view.stats().diagnostics + view.stats().failures < count:
                assert time.monotonic() < deadline, view.stats()
                time.sleep(0.001)
    return view


def test_a_report_is_recorded_as_the_ros_2_message_under_its_ros2msg_schema(
        tmp_path: Path) -> None:
    path = tmp_path / "view.mcap"
    status = sample_status()
    record_reports(path, status)
    [(schema, channel, message, _)] = diagnostics_in(path)
    assert (schema.name, schema.encoding, channel.message_encoding) == (
        "diagnostic_msgs/msg/DiagnosticArray", "ros2msg", "cdr")
    definition = schema.data.decode()
    assert definition.startswith("std_msgs/Header header\nDiagnosticStatus[] status\n")
    assert "\nMSG: diagnostic_msgs/msg/KeyValue\nstring key\nstring value\n" in definition
    # Stamped with the wall clock when the worker took it; the header says the same time.
    assert abs(message.log_time - time.time_ns()) < 60e9
    assert decode_diagnostic_array(message.data) == diagnostic_array(
        status, "rover", HARDWARE, message.log_time)


def test_the_mcap_ros2_decoder_reads_the_report_from_the_schema_alone(tmp_path: Path) -> None:
    decoder = pytest.importorskip(
        "mcap_ros2.decoder", reason="mcap-ros2-support not installed: pip install '.[test]'")
    path = tmp_path / "view.mcap"
    status = sample_status()
    record_reports(path, status)
    [(_, _, message, decoded)] = diagnostics_in(path, [decoder.DecoderFactory()])
    want = diagnostic_array(status, "rover", HARDWARE, message.log_time)
    assert (decoded.header.stamp.sec, decoded.header.stamp.nanosec, decoded.header.frame_id) == (
        want.header.stamp.sec, want.header.stamp.nanosec, "")
    got = [(s.level, s.name, s.message, s.hardware_id, [(v.key, v.value) for v in s.values])
           for s in decoded.status]
    assert got == [(int(s.level), s.name, s.message, s.hardware_id,
                    [(v.key, v.value) for v in s.values]) for s in want.status]
    assert [s.name for s in decoded.status] == [
        "rover: gateway", "rover: CAN bus", "rover: motor left", "rover: motor right"]
    assert decoded.status[2].hardware_id == "odrive node 1 on socketcan:can0"


def test_a_report_that_fails_is_logged_once_and_the_next_goes_out(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    path = tmp_path / "view.mcap"
    view = record_reports(path, object(), sample_status(), object())
    assert (view.stats().diagnostics, view.stats().failures) == (1, 2)
    assert len(diagnostics_in(path)) == 1
    logged = [r for r in caplog.records if "/diagnostics" in r.getMessage()]
    assert len(logged) == 1, [r.getMessage() for r in logged]
