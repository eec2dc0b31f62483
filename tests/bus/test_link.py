"""The bus's bitrate: set on an adapter python-can drives, checked against a SocketCAN
interface (``gateway.bus.link``), and what reaches python-can from every command that opens
a bus."""

from __future__ import annotations

import json
import logging
import shutil
from typing import TYPE_CHECKING, Any

import can
import pytest

import gateway.bus.link as link_module
from gateway.bus.can_bus import open_bus
from gateway.bus.link import Link, bitrate_refusal, down_warning, parse_link, read_link
from gateway.cli import main
from gateway.core.errors import BusError

if TYPE_CHECKING:
    from click.testing import CliRunner


def ip_json(name: str = "can0", kind: str = "can", up: bool = True,
            timing: dict[str, Any] | None = None, state: str | None = "ERROR-ACTIVE") -> str:
    """``ip -details -json link show dev NAME`` as iproute2 prints it (the keys of
    ``ip/iplink_can.c``; the rest of an entry trimmed to a few of its usual keys)."""
    data: dict[str, Any] = {"ctrlmode_supported": ["LOOPBACK", "LISTEN-ONLY", "ONE-SHOT"],
                            "berr_counter": {"tx": 0, "rx": 0}, "restart_ms": 100}
    if state is not None:
        data["state"] = state
    if timing is not None:
        data["bittiming"] = timing
    info: dict[str, Any] = {"info_kind": kind}
    if kind == "can":
        info["info_data"] = data
    flags = ["NOARP", "UP", "LOWER_UP", "ECHO"] if up else ["NOARP", "ECHO"]
    return json.dumps([{"ifindex": 3, "ifname": name, "flags": flags, "mtu": 16,
                        "operstate": "UP" if up else "DOWN", "link_type": "can",
                        "linkinfo": info, "num_tx_queues": 1}])


TIMING_500K = {"bitrate": 500000, "sample_point": "0.875", "tq": 125, "prop_seg": 6,
               "phase_seg1": 7, "phase_seg2": 2, "sjw": 1, "brp": 4}


def test_a_can_interface_states_its_bitrate_and_state() -> None:
    assert parse_link(ip_json(timing=TIMING_500K), "can0") == Link(
        "can0", "can", True, 500000, "ERROR-ACTIVE")
    down = parse_link(ip_json(up=False, timing=TIMING_500K, state="STOPPED"), "can0")
    assert down == Link("can0", "can", False, 500000, "STOPPED")


def test_interfaces_without_bit_timing_state_no_bitrate() -> None:
    assert parse_link(ip_json(timing=None), "can0") == Link(  # never configured
        "can0", "can", True, None, "ERROR-ACTIVE")
    assert parse_link(ip_json("vcan0", "vcan"), "vcan0") == Link(
        "vcan0", "vcan", True, None, None)


@pytest.mark.parametrize("text", [
    "", "not json", "{}", "[]", '[{"ifname": "can1"}]', "[1, 2]",
])
def test_output_without_the_interface_says_nothing(text: str) -> None:
    assert parse_link(text, "can0") is None


@pytest.mark.parametrize("rate", [0, -1, True, "500000", 500000.0, None])
def test_a_bitrate_that_is_not_a_positive_integer_is_not_stated(rate: object) -> None:
    found = parse_link(ip_json(timing={"bitrate": rate}), "can0")
    assert found is not None
    assert found.bitrate is None


@pytest.mark.skipif(shutil.which("ip") is None, reason="no iproute2 here")
def test_read_link_asks_this_machines_kernel() -> None:
    # lo is on every Linux machine: up, no linkinfo, no bitrate; a missing one is not known.
    assert read_link("lo") == Link("lo", "", True, None, None)
    assert read_link("wg-no-such-if") is None


def test_read_link_without_ip_knows_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("shutil.which", lambda _: None)
    assert read_link("can0") is None


def test_a_different_bitrate_is_refused_with_both_fixes() -> None:
    link = Link("can0", "can", True, 500000, "ERROR-ACTIVE")
    assert bitrate_refusal(link, 500000) is None
    text = bitrate_refusal(link, 1000000)
    assert text == (
        "can0 runs at 500000 bit/s but bus.bitrate is 1000000 (every node on a bus must use one "
        "bitrate); if the controllers run at 1000000: sudo ip link set can0 down && sudo ip "
        "link set can0 up type can bitrate 1000000 restart-ms 100; if they run at 500000: set "
        "bus.bitrate to 500000")
    assert bitrate_refusal(Link("vcan0", "vcan", True, None, None), 1000000) is None


def test_an_interface_that_is_down_is_told_how_to_come_up() -> None:
    assert down_warning(Link("can0", "can", True, 500000, None), 500000) is None
    assert down_warning(Link("can0", "can", False, 500000, None), 250000) == (
        "can0 is down: nothing can be sent until it is up (sudo ip link set can0 down && sudo "
        "ip link set can0 up type can bitrate 250000 restart-ms 100)")
    assert down_warning(Link("vcan0", "vcan", False, None, None), 250000) == (
        "vcan0 is down: nothing can be sent until it is up (sudo ip link set vcan0 up)")


@pytest.fixture
def bus_calls(monkeypatch: pytest.MonkeyPatch) -> list[dict[str, Any]]:
    """Every ``can.Bus(...)``'s keyword arguments; the bus then fails to open."""
    calls: list[dict[str, Any]] = []

    def fake(**kwargs: Any) -> can.BusABC:
        calls.append(kwargs)
        raise can.CanInitializationError("no adapter here")

    monkeypatch.setattr(can, "Bus", fake)
    return calls


@pytest.fixture
def links(monkeypatch: pytest.MonkeyPatch) -> dict[str, Link]:
    """The SocketCAN interfaces ``read_link`` finds (none unless a test adds them)."""
    found: dict[str, Link] = {}
    monkeypatch.setattr(link_module, "read_link", found.get)
    return found


@pytest.mark.parametrize("interface", ["pcan", "kvaser", "slcan", "gs_usb", "ixxat", "virtual"])
def test_an_adapter_python_can_drives_is_opened_at_the_bitrate(
    bus_calls: list[dict[str, Any]], interface: str
) -> None:
    with pytest.raises(BusError):
        open_bus(interface, "X", 1000000)
    assert bus_calls[0]["bitrate"] == 1000000
    with pytest.raises(BusError):
        open_bus(interface, "X")  # nobody said one: python-can's (or the adapter's) own
    assert "bitrate" not in bus_calls[1]


def test_a_socketcan_interface_is_checked_not_set(
    bus_calls: list[dict[str, Any]], links: dict[str, Link], caplog: pytest.LogCaptureFixture
) -> None:
    links["can0"] = Link("can0", "can", True, 500000, "ERROR-ACTIVE")
    with pytest.raises(BusError) as info:
        open_bus("socketcan", "can0", 1000000)
    assert str(info.value).startswith(
        "Cannot use CAN bus socketcan:can0: can0 runs at 500000 bit/s but bus.bitrate is 1000000")
    assert bus_calls == []  # refused before python-can opened anything
    with pytest.raises(BusError, match="no adapter here"):
        open_bus("socketcan", "can0", 500000)
    assert "bitrate" not in bus_calls[0]  # (python-can cannot set it on SocketCAN)
    links["can0"] = Link("can0", "can", False, 500000, "STOPPED")
    with caplog.at_level(logging.WARNING), pytest.raises(BusError, match="no adapter here"):
        open_bus("socketcan", "can0", 500000)
    assert [r.getMessage() for r in caplog.records] == [
        "can0 is down: nothing can be sent until it is up (sudo ip link set can0 down && sudo "
        "ip link set can0 up type can bitrate 500000 restart-ms 100)"]
    links["can0"] = Link("can0", "can", True, 250000, "ERROR-ACTIVE")
    with pytest.raises(BusError, match="no adapter here"):  # a reopen asks no ip
        open_bus("socketcan", "can0", 500000, check_link=False)


def test_an_adapter_that_cannot_open_says_what_it_needs_and_the_linux_way(
    bus_calls: list[dict[str, Any]], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("sys.platform", "linux")
    with pytest.raises(BusError) as info:
        open_bus("slcan", "/dev/ttyACM0@115200", 1000000)
    assert str(info.value) == (
        "Cannot open CAN bus slcan:/dev/ttyACM0@115200: no adapter here; python-can's slcan "
        "interface needs pyserial: pip install 'python-can[serial]'; on Linux the kernel's slcan "
        "driver makes this adapter a SocketCAN interface, the usual way there: sudo slcand -o "
        "-s8 /dev/ttyACM0 can0 && sudo ip link set can0 up, then --interface socketcan "
        "--channel can0 (ip -details link show names it)")
    with pytest.raises(BusError) as info:
        open_bus("pcan", "PCAN_USBBUS1", 250000)
    assert "needs PEAK-System's PCAN-Basic library; on Linux the kernel's peak_usb driver" in str(
        info.value)
    assert "sudo ip link set can0 up type can bitrate 250000, then" in str(info.value)
    monkeypatch.setattr("sys.platform", "win32")
    with pytest.raises(BusError) as info:
        open_bus("gs_usb", "0", 500000)
    assert str(info.value).endswith(
        "needs pyusb and gs_usb: pip install 'python-can[gs-usb]'")  # (no Linux advice)
    with pytest.raises(BusError) as info:
        open_bus("ixxat", "0", 500000)
    assert str(info.value) == "Cannot open CAN bus ixxat:0: no adapter here"


@pytest.mark.parametrize(("args", "bitrate"), [
    (["--interface", "pcan", "--channel", "PCAN_USBBUS1", "scan", "--timeout", "0.1"], None),
    (["--interface", "pcan", "--bitrate", "250000", "scan", "--timeout", "0.1"], 250000),
    (["--interface", "pcan", "scan", "-c", "mecanum", "--timeout", "0.1"], 1000000),
    (["--interface", "pcan", "run"], 1000000),  # the embedded robot's
    (["--interface", "pcan", "--bitrate", "250000", "run", "-c", "differential_castor"], 250000),
    (["--interface", "pcan", "monitor", "-c", "mecanum", "--bus", "--once"], 1000000),
    (["--interface", "pcan", "sim", "-c", "mecanum"], 1000000),
    (["--interface", "pcan", "spin", "-c", "mecanum", "front_left", "--speed", "0.5"], 1000000),
])
def test_every_command_that_opens_a_bus_passes_the_bitrate_it_was_told(
    runner: CliRunner, bus_calls: list[dict[str, Any]], args: list[str], bitrate: int | None
) -> None:
    result = runner.invoke(main, args)
    assert "no adapter here" in result.output, result.output
    assert result.exit_code != 0
    assert bus_calls[0]["interface"] == "pcan"
    assert bus_calls[0].get("bitrate") == bitrate


def test_check_warns_of_a_socketcan_interface_at_another_bitrate(
    runner: CliRunner, links: dict[str, Link]
) -> None:
    result = runner.invoke(main, ["check", "-c", "mecanum"])  # can0, 1000000
    assert result.exit_code == 0, result.output
    assert "can0 runs at" not in result.output  # not on this machine: nothing to say
    links["can0"] = Link("can0", "can", True, 500000, "ERROR-ACTIVE")
    result = runner.invoke(main, ["check", "-c", "mecanum"])
    assert result.exit_code == 0, result.output
    assert ("warning:  can0 runs at 500000 bit/s but bus.bitrate is 1000000 (every node on a "
            "bus must use one bitrate)") in result.output
    assert "(wheelgate refuses to use it until they agree)" in result.output
    links["can0"] = Link("can0", "can", False, 1000000, "STOPPED")
    result = runner.invoke(main, ["check", "-c", "mecanum"])
    assert "warning:  can0 is down: nothing can be sent until it is up" in result.output


def test_run_refuses_a_socketcan_interface_at_another_bitrate(
    runner: CliRunner, bus_calls: list[dict[str, Any]], links: dict[str, Link]
) -> None:
    links["can0"] = Link("can0", "can", True, 500000, "ERROR-ACTIVE")
    result = runner.invoke(main, ["--interface", "socketcan", "--channel", "can0", "run"])
    assert result.exit_code == 1, result.output
    assert ("Error: Cannot use CAN bus socketcan:can0: can0 runs at 500000 bit/s but "
            "bus.bitrate is 1000000") in result.output
    assert bus_calls == []  # nothing opened, nothing sent
