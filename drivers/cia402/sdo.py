"""Pure builders and parsers of CANopen SDO frames (expedited transfer only, CiA 301 7.2.4).

An expedited frame is ``[command, index lo, index hi, subindex, d0, d1, d2, d3]``.  The command
byte holds the command specifier in bits 7..5, the number of unused data bytes ``n`` in bits
3..2, and the expedited (``e``) and size-indicated (``s``) flags in bits 1..0: writes of 1, 2 and
4 bytes are ``2F``, ``2B`` and ``23``, their confirmation ``60``; a read is ``40`` and its answer
``4F``/``4B``/``43``; an abort is ``80`` with a 32-bit abort code.  Segmented and block
transfers are not needed for the objects a wheel drive uses and are rejected.

Reference: CiA 301; worked frames in CiA 301 / CiA 402 as the canopen library
(christiansandberg/canopen) implements them.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from drivers.cia402.enums import (
    MAX_NODE_ID,
    ClientCommand,
    CobBase,
    DataType,
    SdoFlag,
    ServerCommand,
    check_node_id,
)
from gateway.core.errors import DecodeError
from gateway.core.types import Frame

_SDO_HEADER = struct.Struct("<BHB")
_SDO_U32 = struct.Struct("<BHBI")


def _initiate_byte(command: int, size: int | None) -> int:
    if size is None:
        return command << 5
    return (command << 5) | ((4 - size) << 2) | SdoFlag.EXPEDITED | SdoFlag.SIZE_INDICATED


def _sdo_frame(cob_id: int, first: int, index: int, subindex: int, payload: bytes) -> Frame:
    DataType.UNSIGNED16.check(index, "an object index")
    DataType.UNSIGNED8.check(subindex, "a subindex")
    return Frame(cob_id, _SDO_HEADER.pack(first, index, subindex) + payload.ljust(4, b"\0"))


def make_sdo_download(
    node_id: int, index: int, subindex: int, value: int, dtype: DataType
) -> Frame:
    """Expedited SDO download request (write), client -> server (0x600 + node).

    :param value: the value, checked against ``dtype``'s range.
    :raises EncodeError: if the value or the address does not fit.
    """
    what = f"0x{index:04X}:{subindex:02X} ({dtype.name})"
    payload = dtype.codec.pack(dtype.check(value, what))
    first = _initiate_byte(ClientCommand.INITIATE_DOWNLOAD, dtype.size)
    return _sdo_frame(CobBase.SDO_RX + check_node_id(node_id), first, index, subindex, payload)


def make_sdo_upload(node_id: int, index: int, subindex: int) -> Frame:
    """SDO upload request (read), client -> server (0x600 + node): ``40 idx idx sub 0 0 0 0``."""
    first = _initiate_byte(ClientCommand.INITIATE_UPLOAD, None)
    return _sdo_frame(CobBase.SDO_RX + check_node_id(node_id), first, index, subindex, b"")


def make_sdo_download_ack(node_id: int, index: int, subindex: int) -> Frame:
    """Server's answer to a download (0x580 + node): ``60 idx idx sub 0 0 0 0``."""
    first = _initiate_byte(ServerCommand.INITIATE_DOWNLOAD, None)
    return _sdo_frame(CobBase.SDO_TX + check_node_id(node_id), first, index, subindex, b"")


def make_sdo_upload_response(
    node_id: int, index: int, subindex: int, value: int, dtype: DataType
) -> Frame:
    """Server's expedited answer to an upload (0x580 + node), size indicated."""
    payload = dtype.codec.pack(dtype.check(value, f"0x{index:04X}:{subindex:02X}"))
    first = _initiate_byte(ServerCommand.INITIATE_UPLOAD, dtype.size)
    return _sdo_frame(CobBase.SDO_TX + check_node_id(node_id), first, index, subindex, payload)


def make_sdo_abort(
    node_id: int, index: int, subindex: int, code: int, *, from_server: bool = True
) -> Frame:
    """SDO abort transfer (``80 idx idx sub code32``), by the server (0x580) or client (0x600)."""
    base = CobBase.SDO_TX if from_server else CobBase.SDO_RX
    DataType.UNSIGNED32.check(code, "an SDO abort code")
    payload = _SDO_U32.pack(ClientCommand.ABORT << 5, index, subindex, code)
    return Frame(base + check_node_id(node_id), payload)


@dataclass(frozen=True, slots=True)
class SdoRequest:
    """An SDO request as the server sees it.

    :param command: initiate download, initiate upload or abort (others are not expedited).
    :param data: the bytes written (download), empty otherwise.
    :param abort_code: the code of an abort, else 0.
    """

    node_id: int
    command: ClientCommand
    index: int
    subindex: int
    data: bytes = b""
    abort_code: int = 0


@dataclass(frozen=True, slots=True)
class SdoResponse:
    """An SDO response as the client sees it.

    :param command: ``INITIATE_DOWNLOAD`` (write confirmed), ``INITIATE_UPLOAD`` (value read)
        or ``ABORT``.
    :param data: the bytes read (upload), empty otherwise.
    :param abort_code: the code of an abort, else 0.
    :param sized: whether the upload indicated its size (CiA 301 7.2.4.3.3, ``s``); an
        expedited upload without it carries "an unspecified number of bytes" in all four.
    """

    node_id: int
    command: ServerCommand
    index: int
    subindex: int
    data: bytes = b""
    abort_code: int = 0
    sized: bool = True

    def value(self, dtype: DataType) -> int:
        """The uploaded value as ``dtype``: of more bytes than the object has, its first bytes
        when the upload did not indicate its size, or when the rest are zero (some devices
        send every value as 32 bits; the python ``canopen`` client, ``SdoClient.upload``,
        truncates the same way).

        :raises DecodeError: if the server sent fewer bytes, or more that are not zero.
        """
        data, size = self.data, dtype.size
        if len(data) > size and (not self.sized or not any(data[size:])):
            return int(dtype.codec.unpack(data[:size])[0])
        if len(data) != size:
            raise DecodeError(
                f"Expected {dtype.size} bytes ({dtype.name}) in the SDO upload of "
                f"0x{self.index:04X}:{self.subindex:02X} from node {self.node_id}, "
                f"but got {len(self.data)}."
            )
        return int(dtype.codec.unpack(self.data)[0])


def _check_sdo_frame(frame: Frame, base: int, who: str) -> int:
    node_id = frame.arbitration_id - base
    if frame.is_extended_id or frame.is_remote_frame or not 1 <= node_id <= MAX_NODE_ID:
        raise DecodeError(
            f"Expected an 11-bit SDO {who} data frame, but got {frame.to_cansend()}."
        )
    if len(frame.data) != 8:
        raise DecodeError(
            f"Expected 8 data bytes in the SDO {who} of node {node_id}, "
            f"but got {len(frame.data)}."
        )
    return node_id


def _expedited_data(first: int, payload: bytes, who: str, node_id: int) -> bytes:
    flags = SdoFlag(first & 0x03)
    if SdoFlag.EXPEDITED not in flags:
        raise DecodeError(
            f"Expected an expedited SDO {who} from node {node_id}, but got command byte "
            f"0x{first:02X} (segmented transfer, not supported)."
        )
    size = 4 - ((first >> 2) & 0x03) if SdoFlag.SIZE_INDICATED in flags else 4
    return payload[:size]


def parse_sdo_response(frame: Frame) -> SdoResponse:
    """Parse a server -> client SDO frame (0x580 + node).

    :raises DecodeError: wrong ID type, DLC or command specifier, or a segmented transfer.
    """
    node_id = _check_sdo_frame(frame, CobBase.SDO_TX, "response")
    first, index, subindex = _SDO_HEADER.unpack_from(frame.data)
    payload = frame.data[4:]
    try:
        command = ServerCommand(first >> 5)
    except ValueError:  # 7 is not defined
        command = None
    if command is ServerCommand.INITIATE_DOWNLOAD:
        return SdoResponse(node_id, command, index, subindex)
    if command is ServerCommand.INITIATE_UPLOAD:
        data = _expedited_data(first, payload, "response", node_id)
        return SdoResponse(node_id, command, index, subindex, data,
                           sized=bool(first & SdoFlag.SIZE_INDICATED))
    if command is ServerCommand.ABORT:
        code = _SDO_U32.unpack(frame.data)[3]
        return SdoResponse(node_id, command, index, subindex, abort_code=code)
    raise DecodeError(
        f"Expected an SDO initiate or abort response from node {node_id}, but got command "
        f"byte 0x{first:02X}."
    )


def parse_sdo_request(frame: Frame) -> SdoRequest:
    """Parse a client -> server SDO frame (0x600 + node), as a simulated drive does.

    :raises DecodeError: wrong ID type, DLC or command specifier, or a segmented transfer.
    """
    node_id = _check_sdo_frame(frame, CobBase.SDO_RX, "request")
    first, index, subindex = _SDO_HEADER.unpack_from(frame.data)
    payload = frame.data[4:]
    try:
        command = ClientCommand(first >> 5)
    except ValueError:
        command = None
    if command is ClientCommand.INITIATE_DOWNLOAD:
        data = _expedited_data(first, payload, "request", node_id)
        return SdoRequest(node_id, command, index, subindex, data)
    if command is ClientCommand.INITIATE_UPLOAD:
        return SdoRequest(node_id, command, index, subindex)
    if command is ClientCommand.ABORT:
        code = _SDO_U32.unpack(frame.data)[3]
        return SdoRequest(node_id, command, index, subindex, abort_code=code)
    raise DecodeError(
        f"Expected an SDO initiate or abort request for node {node_id}, but got command "
        f"byte 0x{first:02X}."
    )


def shown_value(value: int) -> str:
    """An object's value for a message: in hex too where it is a word of bits (a COB-ID)."""
    return f"{value} (0x{value:08X})" if value >= 0x10000 else str(value)
