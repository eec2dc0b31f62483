"""The object dictionary of the simulated CiA 402 drive, with CiA 301 write rules.

It holds the objects the gateway and ``wheelgate scan`` touch (0x1000, 0x1001, 0x1016, 0x1017,
0x1018, 0x1029, PDO parameters 0x1400-0x1403 / 0x1600-0x1603 / 0x1800-0x1803 / 0x1A00-0x1A03, and
0x6007, 0x6040, 0x6041, 0x605A, 0x6060, 0x6061, 0x6064, 0x606C, 0x607A, 0x6084, 0x6085, 0x60FF,
0x6502) and refuses what a real device refuses, with the SDO abort code CiA 301 gives: unknown
object or subindex, read-only, wrong length, a mapping change while the PDO is valid or before
its count is cleared, an unmappable object or more than 64 bits, a COB-ID change of a valid
PDO, an unsupported mode of operation, a heartbeat consumer entry with reserved bits or a node
ID beyond 127, an abort connection option, quick stop option code or error behaviour the device
does not have (0x06090030 "value range of parameter exceeded"), a deceleration of 0 (0x06090032).

Factory values of the protection objects:

* 0x1016 consumer heartbeat time: one entry (sub 0 = 1), sub 1 = 0, "not used" (CiA 301):
  the drive watches nobody until a master writes it;
* 0x1029 error behaviour: sub 0 = 1, sub 1 (communication error: a heartbeat event, bus off) =
  0, "switch to NMT PRE-OPERATIONAL if OPERATIONAL", the CiA 301 default (CiA 301 7.5.2.32;
  1 = no state change, 2 = STOPPED; 3..127 reserved, 128..255 manufacturer-specific, which this
  drive has none of).  CANopenNode does the same by default (``301/CO_NMT_Heartbeat.c``,
  ``CO_NMT_process``: a heartbeat consumer error in OPERATIONAL leads to PRE-OPERATIONAL, or to
  STOPPED with ``CO_NMT_ERR_TO_STOPPED``);
* 0x6007 abort connection option code: 1, fault signal, the CiA 402 profile's default (as,
  e.g., Bonfiglioli's "Vectron Active Cube CM-CAN" manual, chapter "Operational behavior on
  bus failure", gives it: "1 - Error ... (factory setting)");
* 0x605A quick stop option code: 2, quick-stop ramp then SWITCH ON DISABLED (Beckhoff AX8000
  object description 0x605A: default 2);
* 0x6084 profile deceleration, 0x6085 quick stop deceleration: manufacturer-specific; here
  5000 and 10000 RPM/s at the motor, in device velocity units per second (assumptions).

The default PDO mapping is deliberately not the gateway's (Faulhaber-like: RPDO3 = 6040 + 60FF,
TPDO3 = 6041 + 606C, RPDO4/TPDO4 off), so a driver that does not remap fails the tests.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from drivers.cia402.codec import unpack_mapping_entry
from drivers.cia402.enums import (
    PDO_COB_INVALID,
    DataType,
    ObjectIndex,
    OperationMode,
    rpdo_cob_id,
    supported_mode_bit,
    tpdo_cob_id,
)
from drivers.cia402.faults import SdoAbortCode

if TYPE_CHECKING:
    from collections.abc import Iterable

_U8, _U16, _U32 = DataType.UNSIGNED8, DataType.UNSIGNED16, DataType.UNSIGNED32
_I8, _I16, _I32 = DataType.INTEGER8, DataType.INTEGER16, DataType.INTEGER32

#: Abort connection option codes (0x6007) the simulated drive has: 0 no action, 1 fault
#: signal, 2 disable voltage, 3 quick stop (CiA 402; negative codes are manufacturer-specific).
ABORT_OPTIONS = range(4)
#: Quick stop option codes (0x605A) the simulated drive has (CiA 402: 0 to 8).
QUICK_STOP_OPTIONS = range(9)
#: Factory value of 0x6007: 1, fault signal (the profile's default).
FACTORY_ABORT_OPTION = 1
#: Factory value of 0x605A: 2, quick-stop ramp, then SWITCH ON DISABLED.
FACTORY_QUICK_STOP_OPTION = 2
#: Error behaviours (0x1029:01) the simulated drive has: 0 PRE-OPERATIONAL (if OPERATIONAL),
#: 1 no state change, 2 STOPPED (CiA 301).
ERROR_BEHAVIOURS = range(3)
#: Factory value of 0x1029:01: 0, PRE-OPERATIONAL (the CiA 301 default).
FACTORY_ERROR_BEHAVIOUR = 0

#: The identity object 0x1018 (CiA 301: every device has one, at least its vendor-ID):
#: vendor-ID 0 (CiA assigns none to a simulator), product code 0x402, revision number 1.0
#: (major.minor in the high and low 16 bits); the serial number is the node ID.
IDENTITY = (0x00000000, 0x00000402, 0x00010000)

#: Default mappings of PDO 1..4 (entries ``index << 16 | sub << 8 | bits``).
_RPDO_DEFAULTS: tuple[tuple[int, ...], ...] = (
    (0x60400010,), (0x60400010, 0x60600008), (0x60400010, 0x60FF0020), ())
_TPDO_DEFAULTS: tuple[tuple[int, ...], ...] = (
    (0x60410010,), (0x60410010, 0x60610008), (0x60410010, 0x606C0020), ())


@dataclass(slots=True)
class Entry:
    """One object (index, subindex) of the dictionary."""

    dtype: DataType
    value: int
    writable: bool = True
    mappable: bool = False


class SimObjectDictionary:
    """Objects of one simulated node.

    :param node_id: the node (for the predefined PDO COB-IDs).
    :param heartbeat_ms: 0x1017 at power-up.
    :param supported_modes: 0x6502.
    :param missing: indices to leave out.
    :param decelerations: 0x6084 (profile deceleration) and 0x6085 (quick stop deceleration)
        at power-up, device velocity units per second.
    """

    def __init__(self, node_id: int, heartbeat_ms: int, supported_modes: int,
                 missing: Iterable[int] = (), decelerations: tuple[int, int] = (5000, 10000),
                 ) -> None:
        self.node_id = node_id
        self.heartbeat_ms = heartbeat_ms
        self.supported_modes = supported_modes
        self.missing = frozenset(missing)
        self.decelerations = decelerations
        self.entries = self.defaults()

    def defaults(self) -> dict[tuple[int, int], Entry]:
        """Every object at its power-up value."""
        od: dict[tuple[int, int], Entry] = {
            (0x1000, 0): Entry(_U32, 0x00020192, writable=False),
            (0x1001, 0): Entry(_U8, 0, writable=False),
            (0x1016, 0): Entry(_U8, 1, writable=False),
            (0x1016, 1): Entry(_U32, 0),
            (0x1017, 0): Entry(_U16, self.heartbeat_ms),
            (0x1018, 0): Entry(_U8, 4, writable=False),
            (0x1029, 0): Entry(_U8, 1, writable=False),
            (0x1029, 1): Entry(_U8, FACTORY_ERROR_BEHAVIOUR),
            (0x6007, 0): Entry(_I16, FACTORY_ABORT_OPTION),
            (0x6040, 0): Entry(_U16, 0, mappable=True),
            (0x6041, 0): Entry(_U16, 0, writable=False, mappable=True),
            (0x605A, 0): Entry(_I16, FACTORY_QUICK_STOP_OPTION),
            (0x6060, 0): Entry(_I8, OperationMode.PROFILE_POSITION, mappable=True),
            (0x6061, 0): Entry(_I8, OperationMode.PROFILE_POSITION, False, True),
            (0x6064, 0): Entry(_I32, 0, writable=False, mappable=True),
            (0x606C, 0): Entry(_I32, 0, writable=False, mappable=True),
            (0x607A, 0): Entry(_I32, 0, mappable=True),
            (0x6084, 0): Entry(_U32, self.decelerations[0]),
            (0x6085, 0): Entry(_U32, self.decelerations[1]),
            (0x60FF, 0): Entry(_I32, 0, mappable=True),
            (0x6502, 0): Entry(_U32, self.supported_modes, writable=False),
        }
        for sub, value in enumerate((*IDENTITY, self.node_id), start=1):
            od[(0x1018, sub)] = Entry(_U32, value, writable=False)
        n = self.node_id
        for k in range(4):
            off = PDO_COB_INVALID if k == 3 else 0
            od[(0x1400 + k, 0)] = Entry(_U8, 2, writable=False)
            od[(0x1400 + k, 1)] = Entry(_U32, off | rpdo_cob_id(k + 1, n))
            od[(0x1400 + k, 2)] = Entry(_U8, 255)
            od[(0x1800 + k, 0)] = Entry(_U8, 5, writable=False)
            od[(0x1800 + k, 1)] = Entry(_U32, off | tpdo_cob_id(k + 1, n))
            od[(0x1800 + k, 2)] = Entry(_U8, 255)
            od[(0x1800 + k, 3)] = Entry(_U16, 0)
            od[(0x1800 + k, 5)] = Entry(_U16, 0)
            for base, maps in ((0x1600, _RPDO_DEFAULTS), (0x1A00, _TPDO_DEFAULTS)):
                od[(base + k, 0)] = Entry(_U8, len(maps[k]))
                for sub in range(1, 9):
                    value = maps[k][sub - 1] if sub <= len(maps[k]) else 0
                    od[(base + k, sub)] = Entry(_U32, value)
        return {key: e for key, e in od.items() if key[0] not in self.missing}

    def reset_communication(self) -> None:
        """Communication objects (0x1000-0x1FFF) back to their power-up values."""
        self.entries.update({k: e for k, e in self.defaults().items() if k[0] < 0x2000})

    # ----------------------------------------------------------------- access

    def get(self, index: int, subindex: int = 0, default: int = 0) -> int:
        """An object's value, ``default`` if it does not exist."""
        entry = self.entries.get((index, subindex))
        return default if entry is None else entry.value

    def set(self, index: int, value: int, subindex: int = 0) -> None:
        """Set an object the device itself updates (no checks); missing objects are skipped."""
        entry = self.entries.get((index, subindex))
        if entry is not None:
            entry.value = value

    def lookup(self, index: int, subindex: int) -> Entry | SdoAbortCode:
        """The entry, or the abort code for an unknown object or subindex."""
        entry = self.entries.get((index, subindex))
        if entry is not None:
            return entry
        if any(k[0] == index for k in self.entries):
            return SdoAbortCode.SUBINDEX_DOES_NOT_EXIST
        return SdoAbortCode.OBJECT_DOES_NOT_EXIST

    def write(self, index: int, subindex: int, data: bytes, *,
              sdo: bool) -> tuple[int, SdoAbortCode | None]:
        """Write an object from raw little-endian bytes.

        :param sdo: an SDO write (checks the access right); PDO writes skip it.
        :return: ``(value, None)`` on success, ``(0, abort code)`` on refusal.
        """
        entry = self.lookup(index, subindex)
        if isinstance(entry, SdoAbortCode):
            return 0, entry
        if sdo and not entry.writable:
            return 0, SdoAbortCode.WRITE_READ_ONLY
        if len(data) != entry.dtype.size:
            too_high = len(data) > entry.dtype.size
            return 0, SdoAbortCode.LENGTH_TOO_HIGH if too_high else SdoAbortCode.LENGTH_TOO_LOW
        value = int(entry.dtype.codec.unpack(data)[0])
        abort = self._check(index, subindex, value, entry)
        if abort is not None:
            return 0, abort
        entry.value = value
        return value, None

    def _check(self, index: int, sub: int, value: int, entry: Entry) -> SdoAbortCode | None:
        if index == ObjectIndex.CONSUMER_HEARTBEAT_TIME:
            node, time_ms = (value >> 16) & 0xFF, value & 0xFFFF
            reserved = value >> 24
            bad_node = time_ms != 0 and not 1 <= node <= 127
            return SdoAbortCode.INVALID_VALUE if reserved or bad_node else None
        if index == ObjectIndex.ABORT_CONNECTION_OPTION_CODE:
            return None if value in ABORT_OPTIONS else SdoAbortCode.INVALID_VALUE
        if index == ObjectIndex.QUICK_STOP_OPTION_CODE:
            return None if value in QUICK_STOP_OPTIONS else SdoAbortCode.INVALID_VALUE
        if index == ObjectIndex.ERROR_BEHAVIOUR:
            return None if value in ERROR_BEHAVIOURS else SdoAbortCode.INVALID_VALUE
        if index in (ObjectIndex.PROFILE_DECELERATION, ObjectIndex.QUICK_STOP_DECELERATION):
            return SdoAbortCode.VALUE_TOO_LOW if value == 0 else None
        if index == ObjectIndex.MODES_OF_OPERATION:
            try:
                mode = OperationMode(value)
            except ValueError:
                return SdoAbortCode.INVALID_VALUE
            if mode is OperationMode.NO_MODE or not self.supported_modes & supported_mode_bit(mode):
                return SdoAbortCode.INVALID_VALUE
            return None
        if (0x1400 <= index <= 0x1403 or 0x1800 <= index <= 0x1803) and sub == 1:
            both_valid = not (entry.value | value) & PDO_COB_INVALID
            return SdoAbortCode.INVALID_VALUE if both_valid and value != entry.value else None
        if 0x1600 <= index <= 0x1603 or 0x1A00 <= index <= 0x1A03:
            if not self.get(index - 0x200, 1) & PDO_COB_INVALID:
                return SdoAbortCode.CANNOT_STORE_DEVICE_STATE  # PDO valid: no remapping
            if sub == 0:
                return self._check_mapping(index, value)
            if self.get(index, 0) != 0:
                return SdoAbortCode.CANNOT_STORE_DEVICE_STATE  # count not cleared first
        return None

    def _check_mapping(self, index: int, count: int) -> SdoAbortCode | None:
        if count > 8:
            return SdoAbortCode.INVALID_VALUE
        bits = 0
        for sub in range(1, count + 1):
            obj, obj_sub, size = unpack_mapping_entry(self.get(index, sub))
            target = self.entries.get((obj, obj_sub))
            if target is None or not target.mappable or size != 8 * target.dtype.size:
                return SdoAbortCode.CANNOT_MAP_TO_PDO
            if index < 0x1A00 and not target.writable:
                return SdoAbortCode.CANNOT_MAP_TO_PDO
            bits += size
        return SdoAbortCode.PDO_LENGTH_EXCEEDED if bits > 64 else None

    # ----------------------------------------------------------------- PDOs

    def mapped(self, mapping_index: int) -> list[tuple[int, int, int]]:
        """``(index, subindex, bits)`` of each entry of a mapping parameter, in order."""
        return [unpack_mapping_entry(self.get(mapping_index, s))
                for s in range(1, self.get(mapping_index, 0) + 1)]

    def pdo_valid(self, comm_index: int) -> bool:
        """Whether a PDO's COB-ID has bit 31 clear."""
        return (comm_index, 1) in self.entries and not self.get(comm_index, 1) & PDO_COB_INVALID

    def pack(self, mapping_index: int) -> bytes:
        """A TPDO payload: the mapped objects, little endian, in mapping order."""
        out = b""
        for index, sub, _bits in self.mapped(mapping_index):
            entry = self.entries[(index, sub)]
            out += entry.dtype.codec.pack(entry.value)
        return out
