"""What the gateway writes into a CiA 402 node before starting it, as data.

:func:`configuration_steps` lists the steps in order: NMT pre-operational; the command RPDO
and the two feedback TPDOs remapped by SDO, each switched off through COB-ID bit 31 while its
mapping changes; the unused TPDOs switched off; transmission types (1 = every SYNC, or 255 =
event-driven with an event timer); the producer heartbeat time (0x1017); the controller-side
protection (the heartbeat consumer 0x1016:01, the abort connection option code 0x6007 and the
error behaviour 0x1029:01, written and then read back, then, for a quick stop, a read of the
quick stop option code 0x605A, :mod:`drivers.cia402.protection`); the mode of operation
(3, profile velocity, for a drive motor; 8, cyclic synchronous position, for a steering actuator)
and a read-back of 0x6061 until it says so (``canopen``'s ``op_mode`` setter only logs a failed
switch); NMT start.  A steering actuator's command RPDO carries the target position (0x607A)
where a drive motor's carries the target velocity (0x60FF).
:class:`~drivers.cia402.sequence.NodeSequencer` runs them.

Reference: CiA 301 (PDO communication and mapping parameters), CiA 402 (0x6060/0x6061).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from drivers.cia402.codec import (
    RPDO_MAP,
    RPDO_POSITION_MAP,
    TPDO_POSITION_MAP,
    TPDO_VELOCITY_MAP,
    mapping_entry,
)
from drivers.cia402.enums import (
    PDO_COB_INVALID,
    DataType,
    NmtCommand,
    ObjectIndex,
    OperationMode,
    PdoParameter,
    TransmissionType,
    rpdo_cob_id,
    tpdo_cob_id,
)
from drivers.cia402.faults import SdoAbortCode
from drivers.cia402.quick_stop import ABORT_QUICK_STOP, quick_stop_action

if TYPE_CHECKING:
    from collections.abc import Callable

    from drivers.cia402.options import Cia402Options


#: How step descriptions name the modes the driver selects.
MODE_TEXT: dict[OperationMode, str] = {
    OperationMode.PROFILE_VELOCITY: "profile velocity",
    OperationMode.CYCLIC_SYNCHRONOUS_POSITION: "cyclic synchronous position",
}


@dataclass(frozen=True, slots=True)
class NmtStep:
    """Send an NMT command to the node (no answer expected)."""

    command: NmtCommand


@dataclass(frozen=True, slots=True)
class SdoWriteStep:
    """Write one object by expedited SDO download and wait for the confirmation.

    :param protection: part of the controller-side protection: a failure is reported as
        such (:class:`~drivers.cia402.sequence.NodeSequencer` and ``controller_watchdog``).
    :param optional: an object CiA 301 makes optional, whose default is what the write asks
        for: an abort in :data:`ABSENT` is no failure, and the read-back is skipped.
    """

    index: int
    subindex: int
    value: int
    dtype: DataType
    what: str
    protection: bool = False
    optional: bool = False


@dataclass(frozen=True, slots=True)
class SdoExpectStep:
    """Read one object by SDO upload until it equals ``expected`` (or the step times out)."""

    index: int
    subindex: int
    expected: int
    dtype: DataType
    what: str


@dataclass(frozen=True, slots=True)
class SdoVerifyStep:
    """Read one object back once by SDO upload: it must equal ``expected`` (the value just
    written), else the step fails.  Only the controller-side protection uses it."""

    index: int
    subindex: int
    expected: int
    dtype: DataType
    what: str
    protection: bool = True


@dataclass(frozen=True, slots=True)
class SdoReadStep:
    """Read one object once by SDO upload, to report what the drive does; an abort is no
    failure.  ``explain`` turns the value (``None`` if aborted) and the abort code (``None``
    if answered) into a text for the log and whether it deserves a warning."""

    index: int
    subindex: int
    dtype: DataType
    what: str
    explain: Callable[[int | None, int | None], tuple[str, bool]]


Step = NmtStep | SdoWriteStep | SdoExpectStep | SdoVerifyStep | SdoReadStep

#: The SDO aborts of an object or subindex the device does not have (CiA 301).
ABSENT = frozenset({SdoAbortCode.OBJECT_DOES_NOT_EXIST, SdoAbortCode.SUBINDEX_DOES_NOT_EXIST})
#: 0x1029:01 (error behaviour, communication error) as the gateway writes it: 0, NMT
#: PRE-OPERATIONAL (CiA 301 7.5.2.32; 1 would be no state change, 2 STOPPED).
ERROR_BEHAVIOUR_PRE_OPERATIONAL = 0


def _pdo_steps(
    kind: str, number: int, cob_id: int, comm: int, mapping: int,
    entries: tuple[tuple[int, int, int], ...], tx_type: int, event_timer_ms: int | None,
) -> list[Step]:
    name = f"{kind}{number}"
    comm += number - 1
    mapping += number - 1
    u8, u16, u32 = DataType.UNSIGNED8, DataType.UNSIGNED16, DataType.UNSIGNED32
    steps: list[Step] = [
        SdoWriteStep(comm, PdoParameter.COB_ID, PDO_COB_INVALID | cob_id, u32,
                     f"{name} COB-ID, switch off"),
        SdoWriteStep(mapping, 0, 0, u8, f"{name} mapping count, clear"),
    ]
    for sub, (index, subindex, bits) in enumerate(entries, start=1):
        steps.append(SdoWriteStep(mapping, sub, mapping_entry(index, subindex, bits), u32,
                                  f"{name} mapping entry {sub} (0x{index:04X})"))
    steps.append(SdoWriteStep(mapping, 0, len(entries), u8, f"{name} mapping count"))
    steps.append(SdoWriteStep(comm, PdoParameter.TRANSMISSION_TYPE, tx_type, u8,
                              f"{name} transmission type"))
    if event_timer_ms is not None:
        steps.append(SdoWriteStep(comm, PdoParameter.EVENT_TIMER, event_timer_ms, u16,
                                  f"{name} event timer"))
    steps.append(SdoWriteStep(comm, PdoParameter.COB_ID, cob_id, u32, f"{name} COB-ID, on"))
    return steps


def consumer_entry(host_node_id: int, time_ms: int) -> int:
    """A heartbeat consumer entry (0x1016 sub 1..n, CiA 301): the watched node's ID in bits
    23..16, the consumer time in ms in bits 15..0 (0: the entry is not used)."""
    return (host_node_id << 16) | time_ms


def protection_steps(opts: Cia402Options) -> list[Step]:
    """The controller-side protection: 0x1016:01 (watch the gateway's heartbeat), 0x6007
    (abort connection option code) and 0x1029:01 (error behaviour: PRE-OPERATIONAL at the
    heartbeat event; optional, absent is the CiA 301 default) written by expedited SDO, then
    read back; for a quick stop (0x6007 = 3), 0x605A (quick stop option code) read."""
    entry = consumer_entry(opts.host_node_id, opts.consumer_time_ms)
    consumer = (ObjectIndex.CONSUMER_HEARTBEAT_TIME, 1, entry, DataType.UNSIGNED32,
                "heartbeat consumer time")
    option = (ObjectIndex.ABORT_CONNECTION_OPTION_CODE, 0, opts.abort_connection_option,
              DataType.INTEGER16, "abort connection option code")
    behaviour = (ObjectIndex.ERROR_BEHAVIOUR, 1, ERROR_BEHAVIOUR_PRE_OPERATIONAL,
                 DataType.UNSIGNED8, "error behaviour, communication error")
    steps: list[Step] = [
        SdoWriteStep(*consumer, protection=True),
        SdoWriteStep(*option, protection=True),
        SdoWriteStep(*behaviour, protection=True, optional=True),
        SdoVerifyStep(*consumer),
        SdoVerifyStep(*option),
        SdoVerifyStep(*behaviour),
    ]
    if opts.abort_connection_option == ABORT_QUICK_STOP:
        steps.append(SdoReadStep(ObjectIndex.QUICK_STOP_OPTION_CODE, 0, DataType.INTEGER16,
                                 "quick stop option code", quick_stop_action))
    return steps


def configuration_steps(
    node_id: int, opts: Cia402Options, *, position: bool = False
) -> tuple[Step, ...]:
    """Everything written into a node before NMT start, in order, ending with NMT start.

    :param node_id: the node (1..127).
    :param opts: its options (PDO numbers, SYNC or event-driven, heartbeat time, protection).
    :param position: a steering actuator: cyclic synchronous position mode, the target
        position in the command RPDO (else profile velocity mode, the target velocity).
    """
    mode = (OperationMode.CYCLIC_SYNCHRONOUS_POSITION if position
            else OperationMode.PROFILE_VELOCITY)
    lay = opts.layout
    tx_type = TransmissionType.SYNC_EVERY if opts.sync else TransmissionType.EVENT_PROFILE
    timer = None if opts.sync else opts.event_timer_ms
    steps: list[Step] = [NmtStep(NmtCommand.ENTER_PRE_OPERATIONAL)]
    steps += _pdo_steps("RPDO", lay.rpdo, rpdo_cob_id(lay.rpdo, node_id),
                        ObjectIndex.RPDO_COMMUNICATION, ObjectIndex.RPDO_MAPPING,
                        RPDO_POSITION_MAP if position else RPDO_MAP, tx_type, None)
    for number, entries in ((lay.tpdo_position, TPDO_POSITION_MAP),
                            (lay.tpdo_velocity, TPDO_VELOCITY_MAP)):
        steps += _pdo_steps("TPDO", number, tpdo_cob_id(number, node_id),
                            ObjectIndex.TPDO_COMMUNICATION, ObjectIndex.TPDO_MAPPING, entries,
                            tx_type, timer)
    for number in range(1, 5):  # other TPDOs off: they would only load the bus
        if number not in (lay.tpdo_position, lay.tpdo_velocity):
            steps.append(SdoWriteStep(
                ObjectIndex.TPDO_COMMUNICATION + number - 1, PdoParameter.COB_ID,
                PDO_COB_INVALID | tpdo_cob_id(number, node_id), DataType.UNSIGNED32,
                f"TPDO{number} COB-ID, switch off (unused)"))
    steps.append(SdoWriteStep(ObjectIndex.PRODUCER_HEARTBEAT_TIME, 0, opts.heartbeat_ms,
                              DataType.UNSIGNED16, "producer heartbeat time"))
    steps += protection_steps(opts)
    steps += [
        SdoWriteStep(ObjectIndex.MODES_OF_OPERATION, 0, mode, DataType.INTEGER8,
                     f"modes of operation = {MODE_TEXT[mode]}"),
        SdoExpectStep(ObjectIndex.MODES_OF_OPERATION_DISPLAY, 0, mode,
                      DataType.INTEGER8, "modes of operation display"),
        NmtStep(NmtCommand.START),
    ]
    return tuple(steps)
