"""The ODrive axis watchdog: set over CAN on firmware 0.6, stated on 0.5.

The watchdog is the axis' own stop when the host falls silent: ``axis.config.enable_watchdog``
(factory default false) with ``axis.config.watchdog_timeout`` (s).  When it expires in closed
loop, the axis latches WATCHDOG_TIMER_EXPIRED and goes IDLE (the motor coasts).  0.5 feeds it on
every CANSimple frame addressed to the axis (``Firmware/communication/can/can_simple.cpp``,
``do_command`` calls ``axis->watchdog_feed()`` first; the check is ``Axis::watchdog_check`` in
``Firmware/MotorControl/axis.cpp``); the 0.6 firmware is closed, and its official example
(``odriverobotics/ODriveResources``, ``examples/can_watchdog.py``) feeds it with Set_Input_Vel.
The gateway streams Set_Input_Vel (or Set_Input_Pos) every cycle, which feeds it either way.

* **0.5** has no message that writes configuration over CAN: the watchdog is set over USB with
  ``odrivetool`` (``odrv0.axis0.config.watchdog_timeout = 0.2``, ``...enable_watchdog = True``,
  ``odrv0.save_configuration()``) and the motor block states it as ``controller_timeout_s``.
* **0.6** has parameter access: RxSdo (command 0x04) carries ``u8 opcode`` (0 read, 1 write),
  ``u16 endpoint_id``, ``u8 reserved`` and the value; the axis answers reads with TxSdo (0x05)
  in the same layout (``examples/can_param_access.py``).  Endpoint IDs belong to one firmware
  version and board: ODrive publishes a ``flat_endpoints.json`` per release
  (https://docs.odriverobotics.com/releases/firmware).  The motor block names either that file
  (``flat_endpoints``) or the two IDs with their firmware version (``watchdog_endpoints``).  Before
  writing anything the driver asks Get_Version (0x00) and compares the firmware version (and the
  hardware version, when known) with the endpoints': IDs of another version could name another
  parameter, so nothing is written to an axis whose version differs.  Then it writes the
  timeout, then the enable, and reads both back; the axis is armed only once both read back as
  written (:class:`WatchdogSetup`).
"""

from __future__ import annotations

import enum
import json
import math
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from gateway.core.errors import ConfigError
from gateway.core.protection import ProtectionState
from gateway.core.types import Frame

if TYPE_CHECKING:
    from drivers.odrive.options import OdriveOptions

#: RxSdo / TxSdo command IDs (0.6; on 0.5 these are Get_Encoder_Error / Get_Sensorless_Error).
RX_SDO = 0x04
TX_SDO = 0x05
OPCODE_READ = 0
OPCODE_WRITE = 1
#: The two endpoints' paths in ``flat_endpoints.json``.
ENABLE_PATH = "axis0.config.enable_watchdog"
TIMEOUT_PATH = "axis0.config.watchdog_timeout"
#: The timeout written on 0.6 when the motor block does not give ``controller_timeout_s`` (s).
DEFAULT_TIMEOUT_S = 0.25
_HEAD = struct.Struct("<BHB")
_VERSION = struct.Struct("<8B")


@dataclass(frozen=True, slots=True)
class WatchdogEndpoints:
    """Where one firmware version keeps the axis watchdog's settings.

    :param fw_version: ``"major.minor.revision"`` the IDs belong to.
    :param enable_id: endpoint ID of ``axis0.config.enable_watchdog`` (bool).
    :param timeout_id: endpoint ID of ``axis0.config.watchdog_timeout`` (float32, s).
    :param hw_version: ``"product_line.version.variant"``, or ``""`` when not known.
    """

    fw_version: str
    enable_id: int
    timeout_id: int
    hw_version: str = ""

    def read_frame(self, arbitration_id: int, endpoint_id: int, extended: bool) -> Frame:
        """An RxSdo read of ``endpoint_id``."""
        return Frame(arbitration_id, _HEAD.pack(OPCODE_READ, endpoint_id, 0), extended)

    def write_enable(self, arbitration_id: int, extended: bool) -> Frame:
        """An RxSdo write of ``enable_watchdog = true``."""
        data = _HEAD.pack(OPCODE_WRITE, self.enable_id, 0) + struct.pack("<?", True)
        return Frame(arbitration_id, data, extended)

    def write_timeout(self, arbitration_id: int, timeout_s: float, extended: bool) -> Frame:
        """An RxSdo write of ``watchdog_timeout = timeout_s``."""
        data = _HEAD.pack(OPCODE_WRITE, self.timeout_id, 0) + struct.pack("<f", timeout_s)
        return Frame(arbitration_id, data, extended)


def parse_sdo(data: bytes) -> tuple[int, int, bytes] | None:
    """``(opcode, endpoint_id, value bytes)`` of an RxSdo or TxSdo payload, or ``None`` if
    it is shorter than its 4-byte head."""
    if len(data) < _HEAD.size:
        return None
    opcode, endpoint, _ = _HEAD.unpack_from(data)
    return opcode, endpoint, bytes(data[_HEAD.size :])


def parse_version(data: bytes) -> tuple[str, str] | None:
    """``(fw "major.minor.revision", hw "line.version.variant")`` of a Get_Version reply
    (8 bytes: protocol, hw product line, hw version, hw variant, fw major, minor, revision,
    unreleased), or ``None`` for another length."""
    if len(data) != _VERSION.size:
        return None
    _, line, hw, variant, major, minor, revision, _ = _VERSION.unpack(data)
    return f"{major}.{minor}.{revision}", f"{line}.{hw}.{variant}"


def version_reply(fw_version: str, hw_version: str = "") -> bytes:
    """The Get_Version payload an axis with these versions sends (for the simulator)."""
    fw = [int(p) for p in fw_version.split(".")]
    hw = [int(p) for p in hw_version.split(".")] if hw_version else [0, 0, 0]
    return _VERSION.pack(2, *hw, *fw, 0)


# ----------------------------------------------------------------------- configuration


def endpoints_from_options(options: OdriveOptions, where: str) -> WatchdogEndpoints | None:
    """The watchdog endpoints a 0.6 motor block names, or ``None`` if it names none.

    :param options: the motor block's protocol keys (``flat_endpoints``, relative to
        ``config_dir``, or ``watchdog_endpoints``).
    :param where: the motor block, for messages.
    :raises ConfigError: for both keys at once, a missing or unreadable file, a missing
        endpoint or a bad ``watchdog_endpoints`` mapping.
    """
    path, ids = options.flat_endpoints, options.watchdog_endpoints
    if path and ids:
        raise ConfigError(
            f"{where}: expected flat_endpoints or watchdog_endpoints, got both"
        )
    if path:
        config_dir = options.config_dir
        return _from_file(Path(config_dir, path) if config_dir else Path(path), where)
    if ids:
        return _from_mapping(ids, where)
    return None


def _from_file(path: Path, where: str) -> WatchdogEndpoints:
    key = f"{where}.flat_endpoints"
    try:
        if path.stat().st_size > 16 << 20:
            raise ConfigError(f"{key}: {path}: expected at most 16 MiB, got {path.stat().st_size}")
        doc = json.loads(path.read_text(encoding="utf-8"))
    except OSError as err:
        raise ConfigError(f"{key}: cannot read {path}: {err.strerror or err}") from err
    except (ValueError, UnicodeDecodeError) as err:
        raise ConfigError(f"{key}: {path}: expected JSON, got: {err}") from err
    endpoints = doc.get("endpoints") if isinstance(doc, dict) else None
    fw = doc.get("fw_version") if isinstance(doc, dict) else None
    if not isinstance(endpoints, dict) or not isinstance(fw, str):
        raise ConfigError(
            f"{key}: {path}: expected ODrive's flat_endpoints.json with 'fw_version' and "
            f"'endpoints', got keys {sorted(doc) if isinstance(doc, dict) else type(doc).__name__}"
        )
    ids = {}
    for name, path_key, kind in (
        ("enable_watchdog", ENABLE_PATH, "bool"),
        ("watchdog_timeout", TIMEOUT_PATH, "float"),
    ):
        entry = endpoints.get(path_key)
        if not isinstance(entry, dict) or not isinstance(entry.get("id"), int):
            raise ConfigError(
                f"{key}: {path}: expected endpoint {path_key!r} with an id, got {entry!r}"
            )
        if entry.get("type") != kind:
            raise ConfigError(
                f"{key}: {path}: expected {path_key!r} of type {kind!r}, got {entry.get('type')!r}"
            )
        ids[name] = entry["id"]
    hw = doc.get("hw_version", "")
    return _checked(
        fw.partition("-")[0], ids["enable_watchdog"], ids["watchdog_timeout"],
        hw if isinstance(hw, str) else "", key,
    )


def _from_mapping(raw: object, where: str) -> WatchdogEndpoints:
    key = f"{where}.watchdog_endpoints"
    want = {"fw_version", "enable_watchdog", "watchdog_timeout"}
    if not isinstance(raw, dict) or not want <= set(raw) or not set(raw) <= want | {"hw_version"}:
        raise ConfigError(
            f"{key}: expected a mapping with fw_version, enable_watchdog, watchdog_timeout "
            f"(and optionally hw_version), got {raw!r}"
        )
    fw, hw = raw["fw_version"], raw.get("hw_version", "")
    en, to = raw["enable_watchdog"], raw["watchdog_timeout"]
    if not isinstance(fw, str) or not isinstance(hw, str):
        raise ConfigError(
            f"{key}: expected fw_version and hw_version as strings, got {fw!r}, {hw!r}"
        )
    for name, value in (("enable_watchdog", en), ("watchdog_timeout", to)):
        if not isinstance(value, int) or isinstance(value, bool):
            raise ConfigError(f"{key}.{name}: expected an endpoint ID (int), got {value!r}")
    return _checked(fw, en, to, hw, key)


def _checked(fw: str, en: int, to: int, hw: str, key: str) -> WatchdogEndpoints:
    for name, version in (("fw_version", fw), ("hw_version", hw)):
        parts = version.split(".") if version else ["0", "0", "0"]
        if len(parts) != 3 or not all(p.isdigit() and int(p) < 256 for p in parts):
            raise ConfigError(f"{key}.{name}: expected 'a.b.c' (each 0..255), got {version!r}")
    for name, value in (("enable_watchdog", en), ("watchdog_timeout", to)):
        if not 0 <= value <= 0xFFFF:
            raise ConfigError(f"{key}.{name}: expected an endpoint ID 0..65535, got {value}")
    if en == to:
        raise ConfigError(f"{key}: expected two different endpoint IDs, got {en} twice")
    return WatchdogEndpoints(fw, en, to, hw)


# ----------------------------------------------------------------------- the setup


class Step(enum.Enum):
    """Where one axis' watchdog setup stands."""

    IDLE = "not started"
    VERSION = "asked Get_Version"
    READ_BACK = "wrote, reading back"
    CONFIRMED = "confirmed"
    FAILED = "failed"


_STATES = {Step.CONFIRMED: ProtectionState.CONFIRMED, Step.FAILED: ProtectionState.FAILED}


class WatchdogSetup:
    """Set and confirm one 0.6 axis' watchdog: Get_Version, two writes, two reads.

    Pure: :meth:`start` and :meth:`poll` return frames, :meth:`on_version` and
    :meth:`on_tx_sdo` take replies.  Each step is retried after :attr:`RETRY_S`,
    :attr:`ATTEMPTS` times in all, then the setup FAILS with the reason in :attr:`why`.

    :param endpoints: where the firmware keeps the settings.
    :param timeout_s: the watchdog timeout to write (s).
    :param rx_sdo_id: the axis' RxSdo arbitration ID.
    :param version_id: the axis' Get_Version arbitration ID.
    :param extended: 29-bit identifiers.
    """

    RETRY_S = 0.25
    ATTEMPTS = 4

    def __init__(
        self,
        endpoints: WatchdogEndpoints,
        timeout_s: float,
        rx_sdo_id: int,
        version_id: int,
        extended: bool,
    ) -> None:
        self.endpoints = endpoints
        self.timeout_s = timeout_s
        self._rx, self._version, self._ext = rx_sdo_id, version_id, extended
        #: The setup as the driver contract reports it (kept with :attr:`step`): CONFIRMED,
        #: FAILED, or PENDING (not started, or under way); read on every poll.
        self.state = ProtectionState.PENDING
        self._step = Step.IDLE
        #: Why the setup failed (empty otherwise).
        self.why = ""
        self._sent_s = 0.0
        self._attempts = 0
        #: The read-back values, by endpoint ID (``None`` until read).
        self._read: dict[int, object] = {}

    @property
    def step(self) -> Step:
        """Where the setup stands."""
        return self._step

    @step.setter
    def step(self, step: Step) -> None:
        self._step = step
        self.state = _STATES.get(step, ProtectionState.PENDING)

    def start(self, now_s: float) -> list[Frame]:
        """Begin (again): ask Get_Version."""
        self.step, self.why, self._attempts, self._read = Step.VERSION, "", 1, {}
        self._sent_s = now_s
        return [Frame(self._version, b"", self._ext)]

    def poll(self, now_s: float) -> list[Frame]:
        """Retries of the step under way, or the failure once they are used up."""
        if self.step not in (Step.VERSION, Step.READ_BACK) or now_s - self._sent_s < self.RETRY_S:
            return []
        if self._attempts >= self.ATTEMPTS:
            self._fail(self._silence())
            return []
        self._attempts += 1
        self._sent_s = now_s
        if self.step is Step.VERSION:
            return [Frame(self._version, b"", self._ext)]
        return self._write_and_read()

    def on_version(self, fw: str, hw: str, now_s: float) -> list[Frame]:
        """Take a Get_Version reply: write and read back if the versions match."""
        if self.step is not Step.VERSION:
            return []
        ep = self.endpoints
        if fw != ep.fw_version or (ep.hw_version and hw != ep.hw_version):
            self._fail(
                f"the axis reports firmware {fw} (hardware {hw}), the endpoint IDs are for "
                f"firmware {ep.fw_version}" + (f" (hardware {ep.hw_version})" if ep.hw_version
                else "") + "; nothing was written"
            )
            return []
        self.step, self._attempts, self._sent_s = Step.READ_BACK, 1, now_s
        return self._write_and_read()

    def on_tx_sdo(self, endpoint_id: int, value: bytes) -> None:
        """Take a TxSdo reply (a read-back; a 0.6.11+ write confirmation reads the same)."""
        if self.step is not Step.READ_BACK:
            return
        ep = self.endpoints
        if endpoint_id == ep.enable_id and len(value) >= 1:
            self._read[endpoint_id] = bool(value[0])
        elif endpoint_id == ep.timeout_id and len(value) >= 4:
            self._read[endpoint_id] = struct.unpack_from("<f", value)[0]
        else:
            return
        if self._matches():
            self.step = Step.CONFIRMED

    def _matches(self) -> bool:
        ep = self.endpoints
        timeout = self._read.get(ep.timeout_id)
        want = struct.unpack("<f", struct.pack("<f", self.timeout_s))[0]
        return (
            self._read.get(ep.enable_id) is True
            and isinstance(timeout, float)
            and math.isclose(timeout, want, rel_tol=0.0, abs_tol=0.0)
        )

    def _write_and_read(self) -> list[Frame]:
        ep, rx, ext = self.endpoints, self._rx, self._ext
        return [
            ep.write_timeout(rx, self.timeout_s, ext),
            ep.write_enable(rx, ext),
            ep.read_frame(rx, ep.timeout_id, ext),
            ep.read_frame(rx, ep.enable_id, ext),
        ]

    def _silence(self) -> str:
        if self.step is Step.VERSION:
            return f"no Get_Version reply after {self._attempts} requests"
        ep = self.endpoints
        got = {
            "enable_watchdog": self._read.get(ep.enable_id),
            "watchdog_timeout": self._read.get(ep.timeout_id),
        }
        return (
            f"after {self._attempts} writes, read back {got} (expected enable_watchdog True, "
            f"watchdog_timeout {self.timeout_s:g}; endpoints {ep.enable_id}, {ep.timeout_id} "
            f"of firmware {ep.fw_version})"
        )

    def _fail(self, why: str) -> None:
        self.step, self.why = Step.FAILED, why

