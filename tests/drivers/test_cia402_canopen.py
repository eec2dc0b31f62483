"""The CiA 402 SDO client against canopen's server, and canopen's client against the simulated
drive, on a python-can virtual bus: two independent readings of CiA 301
(https://github.com/canopen-python/canopen)."""

from __future__ import annotations

import can
import canopen
import pytest
from canopen.sdo.exceptions import SdoAbortedError

from drivers.cia402.enums import DataType, ServerCommand, State
from drivers.cia402.sdo import make_sdo_download, make_sdo_upload, parse_sdo_response
from drivers.cia402.sim import Cia402Simulator
from gateway.bus.can_bus import send_frames
from gateway.core.types import Frame
from gateway.sim.bus import SimulatedControllers
from tests.drivers.cia402_bench import LEFT


def _od(*entries: tuple[int, int, int]) -> canopen.ObjectDictionary:
    od = canopen.ObjectDictionary()  # type: ignore[no-untyped-call]
    for index, dtype, default in entries:
        var = canopen.objectdictionary.ODVariable(f"x{index:04X}", index, 0)
        var.data_type, var.access_type, var.default = dtype, "rw", default
        od.add_object(var)
    return od


def _recv(bus: can.BusABC, cob: int) -> Frame:
    for _ in range(200):
        msg = bus.recv(0.02)
        if msg is not None and msg.arbitration_id == cob:
            return Frame(cob, bytes(msg.data))
    raise AssertionError(f"no frame 0x{cob:03X}")


def test_our_sdo_client_frames_against_canopen_server(channel: str) -> None:
    net = canopen.Network()
    net.NOTIFIER_CYCLE = 0.02
    node = canopen.LocalNode(3, _od((0x6060, canopen.objectdictionary.INTEGER8, 1),
                                    (0x60FF, canopen.objectdictionary.INTEGER32, 0)))
    net.add_node(node)
    net.connect(interface="virtual", channel=channel)
    gw = can.Bus(interface="virtual", channel=channel)
    try:
        send_frames(gw, [make_sdo_download(3, 0x60FF, 0, -1000, DataType.INTEGER32)])
        ack = parse_sdo_response(_recv(gw, 0x583))
        assert (ack.command, ack.index) == (ServerCommand.INITIATE_DOWNLOAD, 0x60FF)
        assert node.get_data(0x60FF, 0) == (-1000).to_bytes(4, "little", signed=True)
        send_frames(gw, [make_sdo_upload(3, 0x6060, 0)])
        assert parse_sdo_response(_recv(gw, 0x583)).value(DataType.INTEGER8) == 1
        send_frames(gw, [make_sdo_upload(3, 0x2000, 0)])
        abort = parse_sdo_response(_recv(gw, 0x583))
        assert abort.abort_code == 0x06020000
    finally:
        gw.shutdown()
        net.disconnect()


def test_canopen_client_against_our_simulator(channel: str) -> None:
    # An instant device: canopen's client reads 0x6061 and 0x6041 right after each write,
    # within the few ms a drive takes to switch (the driver waits; this client does not).
    sim = Cia402Simulator(LEFT, state_delay_s=0.0, switch_on_delay_s=0.0, enable_delay_s=0.0,
                          mode_switch_delay_s=0.0)
    net = canopen.Network()
    net.NOTIFIER_CYCLE = 0.02
    with SimulatedControllers([sim], channel) as ctl:
        ctl.start()
        node = canopen.RemoteNode(3, canopen.ObjectDictionary())  # type: ignore[no-untyped-call]
        net.add_node(node)
        net.connect(interface="virtual", channel=channel)
        try:
            node.sdo.RESPONSE_TIMEOUT = 2.0
            node.sdo.download(0x6060, 0, b"\x03")
            assert node.sdo.upload(0x6061, 0) == b"\x03"
            assert node.sdo.upload(0x6502, 0) == (0x6D).to_bytes(4, "little")
            node.sdo.download(0x6040, 0, b"\x06\x00")
            assert node.sdo.upload(0x6041, 0)[0] & 0x6F == State.READY_TO_SWITCH_ON
            with pytest.raises(SdoAbortedError) as err:
                node.sdo.upload(0x2000, 0)
            assert err.value.code == 0x06020000
            with pytest.raises(SdoAbortedError) as err:
                node.sdo.download(0x6041, 0, b"\x00\x00")
            assert err.value.code == 0x06010002
            with pytest.raises(SdoAbortedError) as err:  # remap while the PDO is valid
                node.sdo.download(0x1A00, 0, b"\x00")
            assert err.value.code == 0x08000022
        finally:
            net.disconnect()
