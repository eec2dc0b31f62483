"""What ``wheelgate scan`` found, and how it is written: a table (:func:`render`, 80 columns)
and JSON data (:func:`report_json`).  Pure."""

from __future__ import annotations

import textwrap
from collections import Counter
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from gateway.core.types import hex_id
from gateway.drive.scan import Description

if TYPE_CHECKING:
    from gateway.drive.scan import Heard

#: The ``protocol`` of the gateway's own messages, and of identifiers nothing claimed.
WHEELGATE = "wheelgate"
UNKNOWN = "unknown"
#: Columns of the table before the details, and its width.
_HEAD = "{:<9} {:>8}  {:<10} "
WIDTH = 80


@dataclass(frozen=True, slots=True)
class ScannedDevice:
    """One row of the report: a controller, one of the gateway's messages, or an unknown
    identifier.

    :param protocol: ``"odrive"``, ``"vesc"``, ``"canopen"``, ``"dji"`` (a probe's
        :attr:`~gateway.drive.scan.ScanProbe.PROTOCOL`), :data:`WHEELGATE` or :data:`UNKNOWN`.
    :param title: how the table writes it.
    :param driver: the configuration's ``driver:`` for it (``None``: none).
    :param node_id: the controller's node ID (``None`` for the other rows).
    :param extended: whether it uses 29-bit identifiers.
    :param seen_by: what showed the controller.
    :param ids: the traffic on its identifiers.
    :param wheel: the motor block of the configuration with this driver and node ID.
    :param message: the gateway message's name (:data:`WHEELGATE` rows).
    """

    protocol: str
    title: str
    driver: str | None
    node_id: int | None
    extended: bool
    seen_by: str | None
    ids: tuple[Heard, ...]
    description: Description = field(default_factory=Description)
    wheel: str | None = None
    message: str | None = None


@dataclass(frozen=True, slots=True)
class ScanReport:
    """A whole scan.

    :param bus: ``interface:channel``.
    :param duration_s: how long it listened.
    :param rows: the controllers by protocol and node, then the gateway's messages, then the
        unknown identifiers by identifier.
    :param requests_sent: frames the scan sent.
    :param notes: about the scan as a whole.
    """

    bus: str
    duration_s: float
    rows: tuple[ScannedDevice, ...]
    requests_sent: int = 0
    notes: tuple[str, ...] = ()

    @property
    def controllers(self) -> tuple[ScannedDevice, ...]:
        """The rows that are controllers."""
        return tuple(r for r in self.rows if r.node_id is not None)


def _value(value: float | int | str) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def _details(row: ScannedDevice) -> str:
    d = row.description
    parts = [row.message] if row.message else []
    if row.wheel:
        parts.append(f"configured as {row.wheel!r}")
    parts += [x for x in (d.state, d.errors and f"errors {d.errors}",
                          d.firmware and f"firmware {d.firmware}",
                          d.hardware and f"hardware {d.hardware}") if x]
    if d.device_type is not None:
        parts.append(f"device type 0x{d.device_type:08X} (CiA {d.device_type & 0xFFFF})")
    if d.identity is not None:
        named = (("vendor", d.identity.vendor_id), ("product", d.identity.product_code),
                 ("revision", d.identity.revision), ("serial", d.identity.serial))
        parts.append(", ".join(f"{n} 0x{v:08X}" for n, v in named if v is not None))
    if d.readings:
        parts.append(", ".join(f"{n} {_value(v)}" for n, v in d.readings))
    if row.ids:
        parts.append("ids " + ", ".join(f"{hex_id(h.arbitration_id, h.is_extended_id)} "
                                        + ("once" if h.count == 1 else f"{h.rate_hz:.3g}/s")
                                        for h in row.ids))
    parts += d.notes
    return "; ".join(parts)


def _seconds(value: float) -> str:
    return f"{round(value, 2):g}"


def summary(report: ScanReport) -> str:
    """The last line: what was found, where, in how long."""
    found = report.controllers
    if not found:
        return f"no controller answered in {_seconds(report.duration_s)} s on {report.bus}"
    kinds = Counter(r.title for r in found)
    what = ", ".join(f"{n} {title}" for title, n in sorted(kinds.items()))
    plural = "s" if len(found) != 1 else ""
    return (f"{len(found)} controller{plural} ({what}) on {report.bus} in "
            f"{_seconds(report.duration_s)} s; {report.requests_sent} request(s) sent")


def render(report: ScanReport, width: int = WIDTH) -> str:
    """The report as a table of at most ``width`` columns (a details column wrapped), a
    summary line and the notes."""
    head = _HEAD.format("PROTOCOL", "NODE", "FOUND BY")
    indent = " " * len(head)
    lines = []
    if report.rows:
        lines.append(head + "DETAILS")
    for row in report.rows:
        node = "-" if row.node_id is None else str(row.node_id)
        first = _HEAD.format(row.title, node, row.seen_by or "-")
        wrapped = textwrap.wrap(_details(row), max(width - len(head), 20),
                                break_on_hyphens=False) or [""]
        lines.append(first + wrapped[0])
        lines += [indent + w for w in wrapped[1:]]
    lines += [wrap(summary(report), width), *(wrap(f"note: {n}", width) for n in report.notes)]
    return "\n".join(line.rstrip() for line in lines)


def wrap(text: str, width: int = WIDTH) -> str:
    """A line of prose cut to ``width`` columns, the next lines indented by two."""
    return textwrap.fill(text, width, subsequent_indent="  ", break_on_hyphens=False,
                         break_long_words=False)


def _ids_json(ids: tuple[Heard, ...]) -> list[dict[str, Any]]:
    return [{"id": h.arbitration_id, "id_hex": hex_id(h.arbitration_id, h.is_extended_id),
             "extended": h.is_extended_id, "count": h.count, "rate_hz": h.rate_hz}
            for h in ids]


def report_json(report: ScanReport) -> list[dict[str, Any]]:
    """The rows as JSON data: one object each, every key present (``null`` when unknown)."""
    out = []
    for row in report.rows:
        d = row.description
        ident = None if d.identity is None else {
            "vendor_id": d.identity.vendor_id, "product_code": d.identity.product_code,
            "revision": d.identity.revision, "serial": d.identity.serial}
        out.append({
            "protocol": row.protocol, "node_id": row.node_id, "driver": row.driver,
            "extended_id": row.extended, "seen_by": row.seen_by, "wheel": row.wheel,
            "message": row.message, "state": d.state, "errors": d.errors,
            "firmware": d.firmware, "hardware": d.hardware, "device_type": d.device_type,
            "identity": ident, "readings": dict(d.readings), "notes": list(d.notes),
            "ids": _ids_json(row.ids),
        })
    return out
