"""Names for the frames on a robot's bus, for ``wheelgate monitor``.

A frame is named once per (ID, ID type, remote) and the name is cached, so naming costs nothing
per frame.  The facts come from where they live:

* the gateway's own messages: ``gateway.can_ids`` of the configuration and the message names
  of ``config/wheelgate.dbc`` (:mod:`gateway.wire.can`);
* the drivers' frames: every configured motor gets a *probe*, a fresh driver of its protocol
  for that motor alone, which runs a short session on simulated time with the protocol's own
  device simulator (enable sequence, zero-speed commands, housekeeping, disable).  A frame is
  that motor's if it appeared in that session, in either direction, or else if the probe's
  ``on_frame`` claims it.  A frame of several motors of one protocol (a DJI command for four
  ESCs, a CANopen SYNC) names the protocol and every wheel, without a node;
* the message name inside the protocol: the drivers' own enums (ODrive ``CmdId``, VESC
  ``CanPacketId``, CiA 301 ``CobBase``, ``DjiFrameId``) and, for ``dbc``, the message names of
  the motor's DBC file.  Unknown IDs are named by their hex ID.

Probes never touch a bus: they only build and take frames, and their state stays with them.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING

from drivers.cia402.enums import CobBase
from drivers.dji.codec import FEEDBACK_ID_BASE, DjiFrameId
from drivers.odrive.enums import CmdId
from drivers.vesc.codec import CanPacketId
from gateway.core.errors import GatewayError
from gateway.core.types import DriveState, Frame
from gateway.drive.registry import get_driver_class
from gateway.wire.can import ERROR, ODOM_POSE, ODOM_VELOCITY, STATUS, TWIST_CMD

if TYPE_CHECKING:
    from collections.abc import Callable

    from gateway.core.settings import GatewayConfig
    from gateway.core.types import MotorConfig
    from gateway.drive.driver import MotorDriver

log = logging.getLogger(__name__)

#: How the built-in protocols are written in labels (others: their config name).
DRIVER_TITLES = {"odrive": "ODrive", "vesc": "VESC", "cia402": "CiA 402", "dji": "DJI",
                 "dbc": "DBC"}
#: ``gateway.can_ids`` key -> message name in ``config/wheelgate.dbc``.
OWN_MESSAGES = {"twist": TWIST_CMD, "odom_pose": ODOM_POSE, "odom_velocity": ODOM_VELOCITY,
                "status": STATUS, "error": ERROR}
#: Longest simulated session of a probe, and its step, s.
PROBE_S = 2.0
PROBE_STEP_S = 0.005
#: Label source of the gateway's own messages.
GATEWAY = "wheelgate"


@dataclass(frozen=True, slots=True)
class FrameLabel:
    """What a frame is.

    :param text: the whole label, e.g. ``"ODrive node 3 Get_Encoder_Estimates (rear_left)"``.
    :param source: ``"wheelgate"``, a driver's config name, or ``None`` when unknown.
    :param node_id: the controller's node ID when one motor owns the frame.
    :param message: the message name inside the protocol, when known.
    :param wheels: the wheels whose motors own the frame.
    """

    text: str
    source: str | None = None
    node_id: int | None = None
    message: str | None = None
    wheels: tuple[str, ...] = ()


def _odrive_name(frame: Frame) -> str | None:
    cmd = frame.arbitration_id & 0x1F
    try:
        return CmdId(cmd).name.title()
    except ValueError:
        return f"cmd 0x{cmd:02X}"


def _vesc_name(frame: Frame) -> str | None:
    packet = (frame.arbitration_id >> 8) & 0xFF
    try:
        return CanPacketId(packet).name
    except ValueError:
        return f"packet {packet}"


def _cia402_name(frame: Frame) -> str | None:
    can_id = frame.arbitration_id
    if frame.is_extended_id:
        return None
    if can_id == CobBase.NMT:
        return "NMT"
    if can_id == CobBase.SYNC:
        return "SYNC"
    base = can_id & 0x780
    if base == CobBase.EMCY:
        return "EMCY"
    try:
        return CobBase(base).name
    except ValueError:
        return None


def _dji_name(frame: Frame) -> str | None:
    try:
        return DjiFrameId(frame.arbitration_id).name
    except ValueError:
        esc = frame.arbitration_id - FEEDBACK_ID_BASE
        return f"FEEDBACK_ESC_{esc}" if 1 <= esc <= 8 else None


#: Protocol -> message name of a frame of that protocol.
_NAMERS: dict[str, Callable[[Frame], str | None]] = {
    "odrive": _odrive_name, "vesc": _vesc_name, "cia402": _cia402_name, "dji": _dji_name,
}


def _dbc_names(probe: MotorDriver) -> dict[int, str]:
    """Frame ID -> DBC message name of the signals a ``dbc`` motor uses."""
    out: dict[int, str] = {}
    for binding in getattr(probe, "bindings", ()):
        for ref in (binding.command, binding.velocity, binding.position, binding.fault,
                    binding.enable):
            if ref is not None:
                out[int(ref.frame_id)] = str(ref.message_name)
    return out


class FrameLabeler:
    """Names frames of one configured robot.

    :param config: the robot's configuration (motors and ``gateway.can_ids``).
    """

    def __init__(self, config: GatewayConfig) -> None:
        ids = config.loop.can_ids
        self._own = {(getattr(ids, key), ids.extended): name for key, name in OWN_MESSAGES.items()}
        #: (driver name, motor, probe) per configured motor and steering actuator.
        self._probes: list[tuple[str, MotorConfig, MotorDriver]] = []
        for motor in (*config.motors, *config.steering):
            if motor is None:
                continue
            try:
                probe = get_driver_class(motor.driver)([motor])
            except GatewayError as err:
                log.warning("monitor: cannot name the frames of wheel %r: %s", motor.wheel, err)
                continue
            self._probes.append((motor.driver, motor, probe))
        self._dbc: dict[int, str] = {}
        for name, _, probe in self._probes:
            if name == "dbc":
                self._dbc.update(_dbc_names(probe))
        #: (ID, extended) -> indices of the probes whose sessions carried it.
        self._seen: dict[tuple[int, bool], list[int]] = {}
        for k, (_, motor, probe) in enumerate(self._probes):
            for frame in _frames_of(probe, motor):
                owners = self._seen.setdefault((frame.arbitration_id, frame.is_extended_id), [])
                if k not in owners:
                    owners.append(k)
        self._cache: dict[tuple[int, bool, bool], FrameLabel] = {}

    def probes(self) -> list[tuple[MotorConfig, MotorDriver]]:
        """(motor, its probe driver) for every motor whose driver could be loaded."""
        return [(motor, probe) for _, motor, probe in self._probes]

    def label(self, frame: Frame) -> FrameLabel:
        """The label of ``frame`` (cached per ID, ID type and remote flag)."""
        key = (frame.arbitration_id, frame.is_extended_id, frame.is_remote_frame)
        found = self._cache.get(key)
        if found is None:
            found = self._cache[key] = self._describe(frame)
        return found

    def label_id(self, arbitration_id: int, extended: bool) -> FrameLabel:
        """The label of a data frame known only by its ID (the daemon's counts)."""
        return self.label(Frame(arbitration_id, bytes(8), extended))

    def _describe(self, frame: Frame) -> FrameLabel:
        ident = (frame.arbitration_id, frame.is_extended_id)
        rtr = " RTR" if frame.is_remote_frame else ""
        own = self._own.get(ident)
        if own is not None:
            return FrameLabel(f"{own}{rtr}", GATEWAY, None, own)
        owners = self._seen.get(ident)
        if not owners:
            owners = [k for k, (_, _, probe) in enumerate(self._probes) if _claims(probe, frame)]
        if not owners:
            return FrameLabel(_hex(frame) + rtr)
        driver = self._probes[owners[0]][0]
        owners = [k for k in owners if self._probes[k][0] == driver]
        motors = [self._probes[k][1] for k in owners]
        node = motors[0].node_id if len(motors) == 1 else None
        message = self._dbc.get(frame.arbitration_id) if driver == "dbc" else (
            _NAMERS[driver](frame) if driver in _NAMERS else None)
        wheels = tuple(m.wheel for m in motors)
        parts = [DRIVER_TITLES.get(driver, driver)]
        if node is not None:
            parts.append(f"node {node}")
        if message:
            parts.append(message + rtr)
        elif rtr:
            parts.append(rtr.strip())
        parts.append(f"({', '.join(wheels)})")
        return FrameLabel(" ".join(parts), driver, node, message, wheels)


def _hex(frame: Frame) -> str:
    width = 8 if frame.is_extended_id else 3
    return f"0x{frame.arbitration_id:0{width}X}"


def _frames_of(probe: MotorDriver, motor: MotorConfig) -> list[Frame]:
    """Every frame of a short session of ``probe`` with its own device simulator: the enable
    sequence, zero-speed commands and housekeeping until the motor is enabled (at most
    :data:`PROBE_S`), then disabling; both what the driver sends and what the device does.

    Driver log messages are held back meanwhile: a probe's complaints are not the robot's.
    """
    out: list[Frame] = []
    previous = logging.root.manager.disable
    logging.disable(logging.CRITICAL)
    try:
        sim = probe.make_simulator(motor)
        tx = probe.enable(0.0)
        t, enabled_at = 0.0, None
        while t <= PROBE_S and (enabled_at is None or t < enabled_at + PROBE_STEP_S * 5):
            rx = [f for frame in tx for f in sim.handle(frame, t)] + sim.tick(t)
            out += tx + rx
            for frame in rx:
                probe.on_frame(frame.stamped(t))
            if enabled_at is None and probe.status(t)[0].state is DriveState.ENABLED:
                enabled_at = t
            t += PROBE_STEP_S
            tx = probe.poll(t) + probe.command([0.0], t)
        out += probe.disable(t)
    except GatewayError as err:  # a plugin may refuse a step; what was seen still counts
        log.debug("monitor: probe of %r: %s", motor.wheel, err)
    finally:
        logging.disable(previous)
    return out


def _claims(probe: MotorDriver, frame: Frame) -> bool:
    try:
        return probe.on_frame(frame)
    except GatewayError as err:  # drivers count bad frames, but a plugin might raise
        log.debug("monitor: probe %s: %s", type(probe).__name__, err)
        return False
