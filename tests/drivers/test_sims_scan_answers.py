"""What the simulators answer to ``wheelgate scan``'s requests, as the devices do: an ODrive 0.6
answers Get_Version (0.5 has none), a CiA 402 drive has the CiA 301 identity object 0x1018
(read-only), a VESC answers the PING addressed to its ID (a broadcast one with 255)."""

from __future__ import annotations

import pytest

from drivers.cia402.enums import DataType, ServerCommand
from drivers.cia402.faults import SdoAbortCode
from drivers.cia402.sdo import make_sdo_download, make_sdo_upload, parse_sdo_response
from drivers.cia402.sim import Cia402Simulator
from drivers.odrive.sim import OdriveSimulator
from drivers.odrive.watchdog import WatchdogEndpoints
from drivers.vesc.codec import make_ping
from drivers.vesc.sim import VescSimulator
from gateway.core.types import Frame
from tests import factories
from tests.drivers.odrive_helpers import motor


@pytest.mark.parametrize("request_frame", [Frame(0x060, b"", is_remote_frame=True),
                                           Frame(0x060, b"")])
def test_an_odrive_0_6_answers_get_version(request_frame: Frame) -> None:
    """RTR (what the scan sends) or DLC 0 (what the driver sends): 0.0.0 without endpoints,
    the endpoints' versions with them."""
    sim = OdriveSimulator(motor(3, firmware="0.6"))
    assert sim.handle(request_frame, 0.0) == [Frame(0x060, bytes([2, 0, 0, 0, 0, 0, 0, 0]))]
    sim = OdriveSimulator(motor(3, firmware="0.6"),
                          endpoints=WatchdogEndpoints("0.6.10", 201, 200, "4.4.58"))
    assert sim.handle(request_frame, 0.0) == [Frame(0x060, bytes([2, 4, 4, 58, 0, 6, 10, 0]))]


def test_get_version_is_not_answered_where_the_device_does_not() -> None:
    v05 = OdriveSimulator(motor(3, firmware="0.5"))
    assert v05.handle(Frame(0x060, b"", is_remote_frame=True), 0.0) == []
    v06 = OdriveSimulator(motor(3, firmware="0.6"))
    assert v06.handle(Frame(0x060, bytes(8)), 0.0) == []  # an answer, not a request
    assert v06.handle(Frame(0x080, b"", is_remote_frame=True), 0.0) == []  # node 4's


def test_a_cia402_drive_has_the_identity_object() -> None:
    sim = Cia402Simulator(factories.motor("cia402", 5, "left"))
    values = []
    for sub in range(5):
        (answer,) = sim.handle(make_sdo_upload(5, 0x1018, sub), 0.0)
        resp = parse_sdo_response(answer)
        assert resp.command is ServerCommand.INITIATE_UPLOAD
        values.append(resp.value(DataType.UNSIGNED8 if sub == 0 else DataType.UNSIGNED32))
    assert values == [4, 0x00000000, 0x00000402, 0x00010000, 5]
    for sub in range(1, 5):
        (answer,) = sim.handle(make_sdo_download(5, 0x1018, sub, 7, DataType.UNSIGNED32), 0.0)
        resp = parse_sdo_response(answer)
        assert (resp.command, resp.abort_code) == (ServerCommand.ABORT,
                                                   SdoAbortCode.WRITE_READ_ONLY)
    (answer,) = sim.handle(make_sdo_upload(5, 0x1018, 5), 0.0)
    assert parse_sdo_response(answer).abort_code == SdoAbortCode.SUBINDEX_DOES_NOT_EXIST


def test_a_vesc_answers_the_ping_to_its_id() -> None:
    sim = VescSimulator(factories.motor("vesc", 10, "left", options={"pole_pairs": 7}))
    assert sim.handle(make_ping(10, 254), 0.0) == [Frame(0x12FE, bytes([10, 0]), True)]
    assert sim.handle(make_ping(11, 254), 0.0) == []
    assert sim.handle(make_ping(255, 254), 0.0) == [Frame(0x12FE, bytes([255, 0]), True)]
