"""What a protocol tells ``wheelgate scan``: the :class:`ScanProbe` contract.

A scan listens to a bus, asks the controllers it heard a few protocol-defined, read-only
questions, and lists what answered.  Everything that depends on one protocol lives in that
protocol's probe, built on its codec (``drivers/<protocol>/scan.py``), found through
:data:`drivers.BUILTIN_SCANNERS` and the ``gateway.scanners`` entry-point group, as simulators
are: the gateway knows the protocols only through the registries.  The probes are pure (no
I/O, no clock); the scan session (:mod:`gateway.apps.scan.session`) keeps the time, paces the
requests and decides between protocols.

A probe

* recognises its controllers in what was heard (:meth:`ScanProbe.find`), one identifier's
  traffic at a time, with what the identifier and the latest payload show (an ODrive heartbeat,
  a CANopen boot-up);
* states which identifiers belong to a controller it found (:meth:`ScanProbe.owns`) and which
  identifiers every controller of its protocol takes (:meth:`ScanProbe.reserved`): the scan
  lists the former with the controller and never sends another protocol's request on either;
* describes the requests it wants answered (:class:`Request`, as data: the frame and how its
  answer is recognised): per controller found (:meth:`ScanProbe.requests`, sent one after the
  other), and to find controllers that send nothing unasked (:meth:`ScanProbe.discovery`);
* turns what it heard and the answers into a :class:`Description` (:meth:`ScanProbe.describe`).
"""

from __future__ import annotations

import abc
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.core.types import Frame

#: A reading's value in a :class:`Description` (JSON scalars).
Reading = tuple[str, "float | int | str"]


@dataclass(frozen=True, slots=True)
class Heard:
    """The traffic on one identifier during a scan.

    :param count: frames received (data and remote frames; answers to the scan's own
        requests are not counted).
    :param rate_hz: frames per second from the first frame to the latest (a single frame:
        per second of the scan so far).
    :param last: the latest data frame, ``None`` when only remote frames came.
    """

    arbitration_id: int
    is_extended_id: bool
    count: int
    rate_hz: float
    last: Frame | None


@dataclass(frozen=True, slots=True)
class Found:
    """A controller a probe recognised.

    :param node_id: its node ID in the protocol's numbering (a DJI ESC: its feedback ID minus
        0x200).
    :param extended: whether it speaks 29-bit identifiers.
    :param seen_by: what showed it (``"heartbeat"``, ``"boot-up"``, ``"status"``,
        ``"feedback"``, ``"pong"``).
    """

    node_id: int
    extended: bool
    seen_by: str


@dataclass(frozen=True, slots=True)
class Request:
    """One protocol-defined, read-only request, and how its answer is recognised: a data frame
    on ``answer_id`` (of ``answer_extended``) whose bytes from ``answer_offset`` start with
    ``answer_prefix``, with ``answer_dlc`` bytes unless it is -1.

    :param key: what it asks, for notes (``"Get_Version"``, ``"0x1018:01"``, ``"PING"``).
    :param node_id: the controller asked.
    :param frame: the request itself.
    """

    key: str
    node_id: int
    frame: Frame
    answer_id: int
    answer_extended: bool
    answer_prefix: bytes = b""
    answer_offset: int = 0
    answer_dlc: int = -1

    def answered_by(self, frame: Frame) -> bool:
        """Whether ``frame`` is this request's answer."""
        if (frame.is_remote_frame or frame.arbitration_id != self.answer_id
                or frame.is_extended_id != self.answer_extended):
            return False
        if self.answer_dlc >= 0 and frame.dlc != self.answer_dlc:
            return False
        start = self.answer_offset
        return frame.data[start:start + len(self.answer_prefix)] == self.answer_prefix


@dataclass(frozen=True, slots=True)
class Answer:
    """A request that went out, and its answer (``None``: none came in time)."""

    request: Request
    frame: Frame | None


@dataclass(frozen=True, slots=True)
class Identity:
    """A CANopen identity object (0x1018: vendor-ID, product code, revision number, serial
    number); ``None`` for a subindex that was not read."""

    vendor_id: int | None = None
    product_code: int | None = None
    revision: int | None = None
    serial: int | None = None


@dataclass(frozen=True, slots=True)
class Description:
    """What a probe learned of one controller (``None`` and empty: not learned).

    :param state: its state in the protocol's words (``"IDLE"``, ``"pre-operational"``).
    :param errors: ``"none"``, the error flags' names, or the raw word in hex.
    :param firmware: the firmware version it reported.
    :param hardware: the hardware version or type it reported.
    :param device_type: CANopen 0x1000, raw.
    :param identity: CANopen 0x1018.
    :param readings: the latest values it sent unasked, ``(name with unit, value)``.
    :param notes: what is worth knowing beside (an unanswered request, a hint).
    """

    state: str | None = None
    errors: str | None = None
    firmware: str | None = None
    hardware: str | None = None
    device_type: int | None = None
    identity: Identity | None = None
    readings: tuple[Reading, ...] = ()
    notes: tuple[str, ...] = ()


class ScanProbe(abc.ABC):
    """One protocol's side of ``wheelgate scan`` (see the module's doc).  Pure: no I/O, no
    clock, no state between calls."""

    #: The protocol's name in the report (``"odrive"``, ``"canopen"``).
    PROTOCOL: ClassVar[str] = ""
    #: How people write it (``"ODrive"``, ``"CANopen"``).
    TITLE: ClassVar[str] = ""
    #: The configuration's ``driver:`` that speaks it.
    DRIVER: ClassVar[str] = ""
    #: Where the probe stands when two protocols could claim one identifier: lower first (a
    #: protocol whose controllers are told apart by a narrower test goes first; the
    #: identifiers of a controller found are offered to no later probe).
    PRECEDENCE: ClassVar[int] = 100

    @abc.abstractmethod
    def find(self, heard: Sequence[Heard]) -> list[Found]:
        """The controllers this traffic shows (identifiers that other protocols' controllers
        own are left out already)."""

    @abc.abstractmethod
    def owns(self, found: Found, arbitration_id: int, extended: bool) -> bool:
        """Whether the controller ``found`` sends or takes frames with this identifier."""

    def reserved(self, arbitration_id: int, extended: bool) -> bool:
        """Whether every controller of this protocol takes frames with this identifier (a
        broadcast command); no other protocol's request goes there once one is found."""
        return False

    def discovery(self) -> tuple[Request, ...]:
        """Requests that find controllers which send nothing unasked."""
        return ()

    def found_by(self, answer: Answer) -> Found | None:
        """The controller a discovery request's answer shows, if any."""
        return None

    def requests(self, found: Found, heard: Sequence[Heard]) -> tuple[Request, ...]:
        """What to ask a controller found (sent one at a time, in order); ``heard`` is the
        traffic it owns."""
        return ()

    @abc.abstractmethod
    def describe(self, found: Found, heard: Sequence[Heard],
                 answers: Sequence[Answer]) -> Description:
        """What the traffic it owns (``heard``) and its answers (to its requests, and to the
        discovery requests addressed to it) tell of the controller ``found``."""
