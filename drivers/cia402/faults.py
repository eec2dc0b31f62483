"""CANopen error tables: SDO abort codes, EMCY error codes and the error register.

EMCY codes follow CiA 301 (table "Emergency error codes") and CiA 402 (drive-specific codes such
as 0x2310 continuous over-current); each maps onto the gateway's generic
:class:`~gateway.core.types.DriveFault`.  SDO abort texts are the CiA 301 wording as used by
``canopen.sdo.exceptions.SdoAbortedError.CODES`` (https://github.com/canopen-python/canopen),
which the tests check.
"""

from __future__ import annotations

import enum

from gateway.core.types import DriveFault


class SdoAbortCode(enum.IntEnum):
    """SDO abort codes (CiA 301 table "SDO abort codes")."""

    TOGGLE_BIT_NOT_ALTERNATED = 0x05030000
    TIMED_OUT = 0x05040000
    INVALID_COMMAND_SPECIFIER = 0x05040001
    OUT_OF_MEMORY = 0x05040005
    UNSUPPORTED_ACCESS = 0x06010000
    READ_WRITE_ONLY = 0x06010001
    WRITE_READ_ONLY = 0x06010002
    OBJECT_DOES_NOT_EXIST = 0x06020000
    CANNOT_MAP_TO_PDO = 0x06040041
    PDO_LENGTH_EXCEEDED = 0x06040042
    PARAMETER_INCOMPATIBLE = 0x06040043
    INTERNAL_INCOMPATIBILITY = 0x06040047
    HARDWARE_ERROR = 0x06060000
    LENGTH_MISMATCH = 0x06070010
    LENGTH_TOO_HIGH = 0x06070012
    LENGTH_TOO_LOW = 0x06070013
    SUBINDEX_DOES_NOT_EXIST = 0x06090011
    INVALID_VALUE = 0x06090030
    VALUE_TOO_HIGH = 0x06090031
    VALUE_TOO_LOW = 0x06090032
    RESOURCE_NOT_AVAILABLE = 0x060A0023
    GENERAL_ERROR = 0x08000000
    CANNOT_STORE = 0x08000020
    CANNOT_STORE_LOCAL_CONTROL = 0x08000021
    CANNOT_STORE_DEVICE_STATE = 0x08000022
    NO_DATA = 0x08000024


#: Text of each abort code.
SDO_ABORT_TEXT: dict[SdoAbortCode, str] = {
    SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED: "SDO toggle bit error",
    SdoAbortCode.TIMED_OUT: "Timeout of transfer communication detected",
    SdoAbortCode.INVALID_COMMAND_SPECIFIER: "Unknown SDO command specified",
    SdoAbortCode.OUT_OF_MEMORY: "Out of memory",
    SdoAbortCode.UNSUPPORTED_ACCESS: "Unsupported access to an object",
    SdoAbortCode.READ_WRITE_ONLY: "Attempt to read a write only object",
    SdoAbortCode.WRITE_READ_ONLY: "Attempt to write a read only object",
    SdoAbortCode.OBJECT_DOES_NOT_EXIST: "Object does not exist",
    SdoAbortCode.CANNOT_MAP_TO_PDO: "Object cannot be mapped to the PDO",
    SdoAbortCode.PDO_LENGTH_EXCEEDED: "PDO length exceeded",
    SdoAbortCode.PARAMETER_INCOMPATIBLE: "General parameter incompatibility reason",
    SdoAbortCode.INTERNAL_INCOMPATIBILITY: "General internal incompatibility in the device",
    SdoAbortCode.HARDWARE_ERROR: "Access failed due to a hardware error",
    SdoAbortCode.LENGTH_MISMATCH: "Data type and length code do not match",
    SdoAbortCode.LENGTH_TOO_HIGH: "Data type does not match, length of service parameter too high",
    SdoAbortCode.LENGTH_TOO_LOW: "Data type does not match, length of service parameter too low",
    SdoAbortCode.SUBINDEX_DOES_NOT_EXIST: "Subindex does not exist",
    SdoAbortCode.INVALID_VALUE: "Value range of parameter exceeded",
    SdoAbortCode.VALUE_TOO_HIGH: "Value of parameter written too high",
    SdoAbortCode.VALUE_TOO_LOW: "Value of parameter written too low",
    SdoAbortCode.RESOURCE_NOT_AVAILABLE: "Resource not available",
    SdoAbortCode.GENERAL_ERROR: "General error",
    SdoAbortCode.CANNOT_STORE: "Data cannot be transferred or stored to the application",
    SdoAbortCode.CANNOT_STORE_LOCAL_CONTROL: (
        "Data can not be transferred or stored to the application because of local control"
    ),
    SdoAbortCode.CANNOT_STORE_DEVICE_STATE: (
        "Data can not be transferred or stored to the application because of the present "
        "device state"
    ),
    SdoAbortCode.NO_DATA: "No data available",
}


def sdo_abort_text(code: int) -> str:
    """``0x06020000 Object does not exist`` style text for an abort code (known or not)."""
    try:
        text = SDO_ABORT_TEXT[SdoAbortCode(code)]
    except ValueError:
        text = "unknown abort code"
    return f"0x{code:08X} {text}"


class ErrorRegister(enum.IntFlag):
    """The error register (0x1001), byte 2 of every EMCY frame."""

    NONE = 0
    GENERIC = 0x01
    CURRENT = 0x02
    VOLTAGE = 0x04
    TEMPERATURE = 0x08
    COMMUNICATION = 0x10
    DEVICE_PROFILE = 0x20
    RESERVED = 0x40
    MANUFACTURER = 0x80


#: Error register bits that name a fault class by themselves (VOLTAGE does not tell over from
#: under; GENERIC is set with every error).
REGISTER_FAULTS: dict[ErrorRegister, DriveFault] = {
    ErrorRegister.CURRENT: DriveFault.OVER_CURRENT,
    ErrorRegister.TEMPERATURE: DriveFault.OVER_TEMPERATURE,
    ErrorRegister.COMMUNICATION: DriveFault.COMMUNICATION,
}

#: EMCY error codes ``(first, last, fault, text)``, most specific first; the first match wins.
EMCY_CODES: tuple[tuple[int, int, DriveFault, str], ...] = (
    (0x0000, 0x00FF, DriveFault.NONE, "Error reset or no error"),
    (0x2310, 0x2310, DriveFault.OVER_CURRENT, "Continuous over-current"),
    (0x2320, 0x2320, DriveFault.OVER_CURRENT, "Short circuit or earth leakage"),
    (0x2000, 0x2FFF, DriveFault.OVER_CURRENT, "Current"),
    (0x3110, 0x3110, DriveFault.OVER_VOLTAGE, "Mains over-voltage"),
    (0x3120, 0x3120, DriveFault.UNDER_VOLTAGE, "Mains under-voltage"),
    (0x3210, 0x3210, DriveFault.OVER_VOLTAGE, "DC link over-voltage"),
    (0x3220, 0x3220, DriveFault.UNDER_VOLTAGE, "DC link under-voltage"),
    (0x3000, 0x3FFF, DriveFault.OTHER, "Voltage"),
    (0x4210, 0x4210, DriveFault.OVER_TEMPERATURE, "Excess temperature device"),
    (0x4310, 0x4310, DriveFault.OVER_TEMPERATURE, "Excess temperature drive"),
    (0x4000, 0x4FFF, DriveFault.OVER_TEMPERATURE, "Temperature"),
    (0x5000, 0x5FFF, DriveFault.CONTROLLER, "Device hardware"),
    (0x6000, 0x6FFF, DriveFault.CONTROLLER, "Device software"),
    (0x7121, 0x7121, DriveFault.MOTOR, "Motor blocked"),
    (0x7300, 0x73FF, DriveFault.ENCODER, "Sensor"),
    (0x7000, 0x7FFF, DriveFault.MOTOR, "Additional modules"),
    (0x8130, 0x8130, DriveFault.COMMUNICATION, "Life guard or heartbeat error"),
    (0x8250, 0x8250, DriveFault.WATCHDOG, "RPDO timeout"),
    (0x8611, 0x8611, DriveFault.MOTOR, "Following error"),
    (0x8100, 0x82FF, DriveFault.COMMUNICATION, "Communication"),
    (0x8000, 0x8FFF, DriveFault.CONTROLLER, "Monitoring"),
    (0x9000, 0x9FFF, DriveFault.OTHER, "External error"),
    (0xF000, 0xFEFF, DriveFault.OTHER, "Additional functions"),
    (0xFF00, 0xFFFF, DriveFault.OTHER, "Device specific"),
    (0x1000, 0x1FFF, DriveFault.OTHER, "Generic error"),
)


def is_error_reset(code: int) -> bool:
    """Whether an EMCY code means "error reset / no error" (0x00xx)."""
    return code & 0xFF00 == 0


def emcy_description(code: int) -> tuple[DriveFault, str]:
    """The fault class and text of an EMCY error code.

    :param code: the 16-bit error code (bytes 0-1 of the EMCY frame).
    :return: ``(fault, text)``; an unlisted code gives ``(DriveFault.OTHER, "Unknown")``.
    """
    for first, last, fault, text in EMCY_CODES:
        if first <= code <= last:
            return fault, text
    return DriveFault.OTHER, "Unknown"


def emcy_faults(code: int, register: int) -> DriveFault:
    """Generic fault flags of an EMCY: the code's class plus what the error register names.

    A non-reset EMCY never gives ``DriveFault.NONE`` (it falls back to ``OTHER``).
    """
    if is_error_reset(code):
        return DriveFault.NONE
    flags = emcy_description(code)[0]
    reg = ErrorRegister(register & 0xFF)
    for bit, fault in REGISTER_FAULTS.items():
        if bit in reg:
            flags |= fault
    return flags or DriveFault.OTHER


def describe_emcy(code: int, register: int, data: bytes = b"") -> str:
    """One-line text of an EMCY, e.g.
    ``EMCY 0x2310 Continuous over-current (error register 0x03 GENERIC|CURRENT)``.
    """
    text = emcy_description(code)[1]
    reg = ErrorRegister(register & 0xFF)
    names = "|".join(b.name for b in ErrorRegister if b and b in reg and b.name) or "none"
    out = f"EMCY 0x{code:04X} {text} (error register 0x{register:02X} {names}"
    if any(data):
        out += f", data {data.hex(' ').upper()}"
    return out + ")"
