"""CANopen nodes on a scan (:class:`CanopenProbe`, ``wheelgate scan``).

Found by their **boot-up** message or **heartbeat** (CiA 301: COB-ID 0x700 + node, one byte, the
NMT state; a node sends its boot-up once on entering pre-operational, and a heartbeat only when
its producer heartbeat time 0x1017 is set, which is 0 on many devices from the factory).  A node
that booted before the scan and produces no heartbeat is silent, and not found: reset it (power)
during a scan, or set 0x1017.

**Requests: SDO uploads (reads)** of the objects every CANopen device has (CiA 301): 0x1000
device type, then 0x1018 identity, subindex 1 vendor-ID (mandatory), 2 product code, 3 revision
number and 4 serial number (optional: a device without them aborts the read, which the report
says).  One expedited read at a time per node (``40 idx idx sub 00 00 00 00`` to 0x600 + node,
:func:`~drivers.cia402.sdo.make_sdo_upload`); they read and write nothing else and change no
state.  A node in NMT STOPPED serves no SDO (CiA 301), so it is not asked.  Nothing else is
sent: no NMT command, no SDO download, no SYNC.  A running gateway's CiA 402 driver counts the
answers to these reads as "unexpected SDO response" in its status (their object indices are
none it waits for).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from drivers.cia402.enums import (
    MAX_NODE_ID,
    CobBase,
    DataType,
    NmtState,
    ObjectIndex,
    ServerCommand,
)
from drivers.cia402.faults import sdo_abort_text
from drivers.cia402.sdo import make_sdo_upload, parse_sdo_response
from gateway.core.errors import DecodeError
from gateway.drive.scan import Description, Found, Identity, Request, ScanProbe

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.drive.scan import Answer, Heard

#: CiA 301 object 0x1018, the identity object, and its subindices read (name, subindex).
IDENTITY = 0x1018
IDENTITY_FIELDS = (("vendor_id", 1), ("product_code", 2), ("revision", 3), ("serial", 4))
#: The function codes of one node's COB-IDs in the predefined connection set (CiA 301).
_NODE_BASES = frozenset({CobBase.EMCY, CobBase.TPDO1, CobBase.RPDO1, CobBase.TPDO2,
                         CobBase.RPDO2, CobBase.TPDO3, CobBase.RPDO3, CobBase.TPDO4,
                         CobBase.RPDO4, CobBase.SDO_TX, CobBase.SDO_RX, CobBase.HEARTBEAT})
#: COB-IDs every node takes: NMT, SYNC, TIME, and the LSS master's request (CiA 305).
_BROADCAST = frozenset({int(CobBase.NMT), int(CobBase.SYNC), int(CobBase.TIME), 0x7E5})
_STATE_WORDS = {NmtState.BOOT_UP: "booted (pre-operational)", NmtState.STOPPED: "stopped",
                NmtState.OPERATIONAL: "operational",
                NmtState.PRE_OPERATIONAL: "pre-operational"}


def nmt_state(heard: Heard) -> NmtState | None:
    """The NMT state a heartbeat identifier's latest frame carries (``None``: not one)."""
    node = heard.arbitration_id - CobBase.HEARTBEAT
    frame = heard.last
    if heard.is_extended_id or not 1 <= node <= MAX_NODE_ID or frame is None or frame.dlc != 1:
        return None
    try:
        return NmtState(frame.data[0] & 0x7F)  # bit 7: node guarding's toggle
    except ValueError:
        return None


def _key(index: int, subindex: int) -> str:
    return f"0x{index:04X}:{subindex:02X}"


class CanopenProbe(ScanProbe):
    """CANopen (CiA 301) nodes, by boot-up and heartbeat; device type and identity read by
    SDO (see the module)."""

    PROTOCOL: ClassVar[str] = "canopen"
    TITLE: ClassVar[str] = "CANopen"
    DRIVER: ClassVar[str] = "cia402"
    #: First: one byte on 0x701..0x77F holding an NMT state is the narrowest test of all.
    PRECEDENCE: ClassVar[int] = 10

    def find(self, heard: Sequence[Heard]) -> list[Found]:
        out = []
        for h in heard:
            state = nmt_state(h)
            if state is not None:
                seen = "boot-up" if state is NmtState.BOOT_UP and h.count == 1 else "heartbeat"
                out.append(Found(h.arbitration_id - CobBase.HEARTBEAT, False, seen))
        return out

    def owns(self, found: Found, arbitration_id: int, extended: bool) -> bool:
        node = arbitration_id & 0x7F
        return not extended and node == found.node_id and (arbitration_id - node) in _NODE_BASES

    def reserved(self, arbitration_id: int, extended: bool) -> bool:
        return not extended and arbitration_id in _BROADCAST

    def requests(self, found: Found, heard: Sequence[Heard]) -> tuple[Request, ...]:
        if _state(found, heard) is NmtState.STOPPED:
            return ()
        reads = [(ObjectIndex.DEVICE_TYPE, 0)] + [(IDENTITY, sub) for _, sub in IDENTITY_FIELDS]
        out = []
        for index, sub in reads:
            frame = make_sdo_upload(found.node_id, index, sub)
            out.append(Request(_key(index, sub), found.node_id, frame,
                               CobBase.SDO_TX + found.node_id, False, frame.data[1:4], 1, 8))
        return tuple(out)

    def describe(self, found: Found, heard: Sequence[Heard],
                 answers: Sequence[Answer]) -> Description:
        state = _state(found, heard)
        values: dict[str, int] = {}
        notes = []
        if state is NmtState.STOPPED:
            notes.append("NMT STOPPED: it serves no SDO there, so nothing was asked")
        silent = bool(answers) and all(a.frame is None for a in answers)
        if silent:
            notes.append("no answer to any SDO read: not an SDO server (a master's heartbeat, "
                         "such as a gateway's host_node_id), or gone")
        for a in answers:
            key = a.request.key
            if a.frame is None:
                if not silent:
                    notes.append(f"no answer to the SDO read of {key}")
                continue
            try:
                resp = parse_sdo_response(a.frame)
                if resp.command is ServerCommand.ABORT:
                    notes.append(f"SDO read of {key} aborted: {sdo_abort_text(resp.abort_code)}")
                    continue
                values[key] = resp.value(DataType.UNSIGNED32)
            except DecodeError as err:
                notes.append(f"SDO read of {key}: {err}")
        identity = None
        fields = {name: values.get(_key(IDENTITY, sub)) for name, sub in IDENTITY_FIELDS}
        if any(v is not None for v in fields.values()):
            identity = Identity(**fields)
        return Description(
            state=None if state is None else _STATE_WORDS[state],
            device_type=values.get(_key(ObjectIndex.DEVICE_TYPE, 0)),
            identity=identity, notes=tuple(notes))


def _state(found: Found, heard: Sequence[Heard]) -> NmtState | None:
    """The NMT state of the node's latest boot-up or heartbeat."""
    for h in heard:
        if h.arbitration_id == CobBase.HEARTBEAT + found.node_id:
            return nmt_state(h)
    return None
