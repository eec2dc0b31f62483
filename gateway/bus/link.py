"""A SocketCAN interface as the kernel has it set up: up or down, and its bitrate.

python-can cannot set a SocketCAN interface's bitrate (the kernel owns it: ``ip link set can0
up type can bitrate N``), so a configuration's ``bus.bitrate`` and the interface can disagree
without anything saying so: the controllers then answer nothing, or the bus fills with error
frames.  :func:`read_link` asks iproute2 (``ip -details -json link show dev NAME``, as
python-can's own ``can.interfaces.socketcan.utils.find_available_interfaces`` asks ``ip -json
link``) and :func:`bitrate_refusal` says what to do about a difference.

The JSON is iproute2's (``ip/iplink_can.c``: ``linkinfo.info_kind`` ``"can"``,
``linkinfo.info_data.bittiming.bitrate``, ``linkinfo.info_data.state``); a virtual interface
(``vcan``, ``vxcan``) has no bit timing, and a CAN interface never configured has none either:
both are taken as stating no bitrate.
"""

from __future__ import annotations

import json
import logging
import shutil
import subprocess
from dataclasses import dataclass

log = logging.getLogger(__name__)

#: Seconds ``ip`` may take (it answers in milliseconds; a hung one must not hold a start).
IP_TIMEOUT_S = 2.0


@dataclass(frozen=True, slots=True)
class Link:
    """One network interface as ``ip -details -json link show`` describes it.

    :param name: the interface (``can0``).
    :param kind: ``linkinfo.info_kind`` (``can``, ``vcan``, ``vxcan``; empty for an interface
        without one, such as ``lo``).
    :param up: administratively up (``UP`` among its flags).
    :param bitrate: the nominal bitrate (bit/s) of its bit timing, ``None`` when it states none.
    :param state: the CAN controller's state (``ERROR-ACTIVE``, ``BUS-OFF``, ``STOPPED`` ...),
        ``None`` when not stated.
    """

    name: str
    kind: str
    up: bool
    bitrate: int | None
    state: str | None

    def up_command(self, bitrate: int | str) -> str:
        """The commands that bring this interface up at ``bitrate`` (as root; a placeholder
        such as ``N`` when the bitrate is not known)."""
        return (f"sudo ip link set {self.name} down && sudo ip link set {self.name} up type can "
                f"bitrate {bitrate} restart-ms 100")


def parse_link(text: str, name: str) -> Link | None:
    """The interface ``name`` in the output of ``ip -details -json link show``.

    :return: ``None`` when the output is not iproute2's JSON or does not hold ``name``.
    """
    try:
        doc = json.loads(text)
    except ValueError:
        return None
    if not isinstance(doc, list):
        return None
    for entry in doc:
        if isinstance(entry, dict) and entry.get("ifname") == name:
            return _link(entry, name)
    return None


def _link(entry: dict[str, object], name: str) -> Link:
    flags = entry.get("flags")
    up = isinstance(flags, list) and "UP" in flags
    info = entry.get("linkinfo")
    info = info if isinstance(info, dict) else {}
    kind = info.get("info_kind")
    data = info.get("info_data")
    data = data if isinstance(data, dict) else {}
    timing = data.get("bittiming")
    rate = timing.get("bitrate") if isinstance(timing, dict) else None
    state = data.get("state")
    return Link(name, kind if isinstance(kind, str) else "", up,
                rate if isinstance(rate, int) and not isinstance(rate, bool) and rate > 0
                else None,
                state if isinstance(state, str) else None)


def read_link(name: str) -> Link | None:
    """Interface ``name`` as the kernel has it, through ``ip``.

    :return: ``None`` when there is no ``ip`` here, it fails (no such interface, no Linux), or
        its output cannot be read: nothing is known then, and nothing is refused for it.
    """
    ip = shutil.which("ip") or next(
        (p for p in ("/usr/sbin/ip", "/sbin/ip") if shutil.which(p)), None)
    if ip is None:
        log.debug("no ip command here: the bitrate of %s is not checked", name)
        return None
    try:
        done = subprocess.run([ip, "-details", "-json", "link", "show", "dev", name],
                              capture_output=True, text=True, timeout=IP_TIMEOUT_S, check=False)
    except (OSError, subprocess.SubprocessError) as err:
        log.debug("ip link show %s failed (%s): its bitrate is not checked", name, err)
        return None
    if done.returncode != 0:
        log.debug("ip link show %s: %s", name, done.stderr.strip())
        return None
    return parse_link(done.stdout, name)


def bitrate_refusal(link: Link, bitrate: int, said: str = "bus.bitrate") -> str | None:
    """Why wheelgate must not use ``link`` for a bus at ``bitrate``, ``None`` when it may.

    The interface states another bitrate: every node of a bus must use one, so either the
    interface or the configuration is wrong, and the message gives the fix of each.
    """
    if link.bitrate is None or link.bitrate == bitrate:
        return None
    return (f"{link.name} runs at {link.bitrate} bit/s but {said} is {bitrate} (every node on a "
            f"bus must use one bitrate); if the controllers run at {bitrate}: "
            f"{link.up_command(bitrate)}; if they run at {link.bitrate}: set {said} to "
            f"{link.bitrate}")


def down_warning(link: Link, bitrate: int) -> str | None:
    """What to do about an interface that is down, ``None`` when it is up."""
    if link.up:
        return None
    up = link.up_command(bitrate) if link.kind == "can" else f"sudo ip link set {link.name} up"
    return f"{link.name} is down: nothing can be sent until it is up ({up})"


def judge_link(channel: str, bitrate: int) -> tuple[str | None, str | None]:
    """SocketCAN interface ``channel`` here for a bus at ``bitrate``: why it must not be used
    (:func:`bitrate_refusal`) and what to warn of (:func:`down_warning`), each ``None`` when
    nothing (nothing at all when it is not here)."""
    link = read_link(channel)
    if link is None:
        return None, None
    refusal = bitrate_refusal(link, bitrate)
    return refusal, None if refusal is not None else down_warning(link, bitrate)


def link_warnings(channel: str, bitrate: int) -> list[str]:
    """:func:`judge_link` as ``check`` warns of it (the interface may still be set up before
    the gateway starts: a unit's ``ExecStartPre=``, systemd-networkd)."""
    refusal, warning = judge_link(channel, bitrate)
    if refusal is not None:
        return [f"{refusal} (wheelgate refuses to use it until they agree)"]
    return [] if warning is None else [warning]
