"""``wheelgate monitor``'s screen: a :class:`~gateway.apps.monitor.view.MonitorSnapshot` as
text that fits the terminal.

Without a height (a pipe, ``--once``) everything is written, a motor a row.  In a terminal
(:mod:`gateway.apps.layout`) the sections give way to the height: the motors condense to one
row per wheel (its speed and its steering actuator's angle), the header, the bus line and the
errors to a line each (the errors to those that are not zero); the frame IDs take the rows
left and are paged.  Below 100 columns the motor table leaves out the driver and the wheel
angle.  A steering actuator shows its angle in degrees, beside or under its wheel.  Faults,
and a gateway in fault or emergency stop, are red; offline motors, error counts and notes
yellow, when colour is asked for.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from gateway.apps.layout import Level, Line, cut, fit, pack, paint, pair_steering, wrap
from gateway.apps.monitor.view import error_class_of
from gateway.core.numfmt import fixed
from gateway.core.types import hex_id

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.apps.monitor.view import MonitorSnapshot, MotorView

__all__ = ["render"]

#: Narrower than this, the motor table leaves out the driver and the wheel angle.
WIDE = 100
#: Rows the frame IDs keep (their header, six IDs and the page line) until the motors have
#: condensed; then three, then none, before the motors are cut.  They take every row left.
MIN_ID_ROWS = 8
#: Stands for the frame IDs while the other sections are fitted.
_IDS = Line("\0frame IDs")


def _error_items(errors: Sequence[tuple[str, int]], nonzero: bool) -> list[str]:
    """The error counters as ``name count`` items (``nonzero``: only those that are not 0),
    the error frames by class in parentheses after their total: ``bus error frames 3 (no ack
    2, bus off 1)``."""
    items: list[str] = []
    classes: dict[int, list[str]] = {}
    for name, n in errors:
        if nonzero and not n:
            continue
        kind = error_class_of(name)
        if kind is not None and items:
            classes.setdefault(len(items) - 1, []).append(f"{kind} {n}")
        else:
            items.append(f"{name} {n}")
    return [item + (f" ({', '.join(classes[i])})" if i in classes else "")
            for i, item in enumerate(items)]


def _clock(snap: MonitorSnapshot) -> str:
    """Where the snapshot is in time, for a person: into the log, or since watching began."""
    if snap.source.startswith("log "):
        return f"{fixed(snap.elapsed_s, 3)} s into the log"
    return f"watching for {fixed(snap.elapsed_s, 1)} s"


def _num(value: float | None, places: int, scale: float = 1.0) -> str:
    return "-" if value is None else fixed(value * scale, places)


def _level(*motors: MotorView) -> Level:
    if any(m.faults or m.state == "fault" for m in motors):
        return Level.ERROR
    return Level.WARNING if any(m.state == "offline" for m in motors) else Level.PLAIN


def _faults(m: MotorView) -> str:
    return ", ".join(m.faults) + (f" {m.detail}" if m.detail else "")


class _Table:
    """The motor table: a row per motor (an actuator under its wheel) or a row per wheel."""

    def __init__(self, motors: Sequence[MotorView], wide: bool) -> None:
        self.motors = motors
        steers = {m.name: m.steers for m in motors if m.steers}
        self.pairs = pair_steering([m.name for m in motors], steers)
        self.steered = bool(steers)
        self.wide = wide
        names = [len(motors[i].name) for i, _ in self.pairs]
        self.name_w = min(max([13 if wide else 7, *names]) + 1, 21)

    def _row(self, c: dict[str, str], level: Level = Level.PLAIN) -> Line:
        n = self.name_w
        steer = f"{c['steer']:>11}" if self.steered else ""
        if self.wide:
            text = (f"{cut(c['name'], n - 1):<{n}}{cut(c['driver'], 8):<8}{c['node']:>4}  "
                    f"{c['state']:<9}"
                    f"{c['rad_s']:>9}{c['rpm']:>9}{c['pos']:>11}{steer}{c['age']:>9}  ")
            return Line(text + c["faults"], level, n + 14)
        text = (f"{cut(c['name'], n - 1):<{n}}{c['node']:>5}  {c['state']:<9}{c['rad_s']:>9}"
                f"{c['rpm']:>8}{steer}{c['age']:>8}  ")
        return Line(text + c["faults"], level, n + 7)

    def header(self) -> Line:
        return self._row({"name": "MOTOR" if self.wide else "WHEEL", "driver": "DRIVER",
                          "node": "NODE", "state": "STATE", "rad_s": "rad/s",
                          "rpm": "rpm", "pos": "pos rad", "steer": "steer deg",
                          "age": "age ms", "faults": "FAULTS"})

    @staticmethod
    def _cells(m: MotorView, name: str = "") -> dict[str, str]:
        angle = "" if not m.steers or m.position_rad is None else fixed(
            math.degrees(m.position_rad), 1, sign=True)
        return {"name": name or m.name, "driver": m.driver, "node": str(m.node_id),
                "state": m.state, "rad_s": _num(m.velocity_rad_s, 3),
                "rpm": _num(m.motor_rpm, 1), "pos": _num(m.position_rad, 3),
                "steer": angle, "age": _num(m.feedback_age_s, 1, 1000.0),
                "faults": _faults(m) or "-"}

    def each(self) -> list[Line]:
        out = []
        for i, j in self.pairs:
            out.append(self._row(self._cells(self.motors[i]), _level(self.motors[i])))
            if j is not None:
                a = self.motors[j]
                out.append(self._row(self._cells(a, "  steering"), _level(a)))
        return out

    def merged(self) -> list[Line]:
        out = []
        for i, j in self.pairs:
            m = self.motors[i]
            c = self._cells(m)
            if j is not None:
                a = self.motors[j]
                steer = self._cells(a)
                c["node"] = f"{m.node_id}/{a.node_id}"
                c["steer"] = steer["steer"]
                if a.faults or (a.state != m.state and a.state not in ("enabled", "online")):
                    note = f"steering {a.state}" + (f": {_faults(a)}" if a.faults else "")
                    c["faults"] = note if c["faults"] == "-" else f"{c['faults']}; {note}"
                out.append(self._row(c, _level(m, a)))
            else:
                out.append(self._row(c, _level(m)))
        return out


def _motors(snap: MonitorSnapshot, width: int) -> list[list[Line]]:
    table = _Table(snap.motors, width >= WIDE)
    merged = table.merged()
    out = [[table.header(), *table.each()], [table.header(), *merged]]
    for keep in range(len(merged) - 1, -1, -1):
        out.append([table.header(), *merged[:keep],
                    Line(f"... {len(merged) - keep} more motors (a taller terminal shows them)")])
    return out


def _ids(snap: MonitorSnapshot, rows: int | None, page: int, keys: bool) -> list[Line]:
    """The frame IDs in ``rows`` lines (``None``: all), on page ``page`` (modulo the pages)."""
    id_w = max([5, *(len(hex_id(i.arbitration_id, i.extended)) for i in snap.ids)]) + 1
    lines = [Line(f"{hex_id(i.arbitration_id, i.extended):<{id_w}}{i.direction:<3}"
                  f"{fixed(i.rate_hz, 1):>9}{i.count:10d}  {i.label.text}") for i in snap.ids]
    header = Line(f"{'ID':<{id_w}}{'DIR':<3}{'RATE Hz':>9}{'COUNT':>10}  MESSAGE")
    if rows is None or len(lines) < rows:
        return [header, *lines]
    per_page = max(rows - 2, 1)
    pages = math.ceil(len(lines) / per_page)
    first = page % pages * per_page
    shown = lines[first:first + per_page]
    how = "space: next page, b: previous" if keys else "a taller terminal shows more"
    return [header, *shown, Line(f"IDs {first + 1}-{first + len(shown)} of {len(lines)}, "
                                 f"page {page % pages + 1}/{pages} ({how})")]


def render(snap: MonitorSnapshot, width: int = WIDE, height: int | None = None, page: int = 0,
           colour: bool = False, keys: bool = False) -> str:
    """The snapshot as text lines no wider than ``width`` characters.

    :param height: at most this many lines (``None``: as many as it takes).
    :param page: the page of frame IDs shown when they do not all fit (modulo the pages).
    :param colour: colour faults, errors and warnings (ANSI SGR).
    :param keys: the keys ``q`` and space/``b`` work (the screen says so).
    """
    load = snap.load
    worst = "n/a" if load.worst_percent is None else f"{fixed(load.worst_percent, 1)} %"
    head = [f"wheelgate monitor: {snap.source}",
            _clock(snap),
            *([f"gateway {snap.state}"] if snap.state else []), *(["q: quit"] if keys else [])]
    bad = Level.ERROR if snap.state in ("fault", "estop") else Level.PLAIN
    bus = [f"bus {load.bitrate / 1000:g} kbit/s",
           f"load {fixed(load.nominal_percent, 1)} % nominal, {worst} worst case",
           *([] if load.budget_percent is None else [
               f"budget {fixed(load.budget_percent[0], 1)}-{fixed(load.budget_percent[1], 1)} %"]),
           f"{fixed(load.frames_per_s, 0)} frames/s over {fixed(snap.window_s, 2)} s",
           f"{snap.frames} frames"]
    counts = _error_items(snap.errors, nonzero=False)
    nonzero = _error_items(snap.errors, nonzero=True)
    if len(nonzero) < len(counts):
        nonzero = [*nonzero, "others 0"] if nonzero else ["none"]
    warn = Level.WARNING if nonzero and nonzero != ["none"] else Level.PLAIN
    notes = [f"note: {note}" for note in snap.notes]

    def errors(listed: list[str], n: int) -> list[Line]:
        return pack([f"errors: {listed[0]}", *listed[1:]] if listed else ["errors: -"],
                    width, n, warn, 8, ", ")

    sections: list[list[list[Line]]] = [
        [pack(head, width, n, bad) for n in (2, 1)],
        [pack(bus, width, n) for n in (2, 1)],
        [[Line("")], []],
        _motors(snap, width),
        [[Line("")], []],
        [[_IDS] * n for n in (MIN_ID_ROWS, 3, 0)] if height is not None else [[_IDS]],
        [[Line("")], []],
        [errors(counts, 3), errors(nonzero, 2), errors(nonzero, 1)],
        [[ln for note in notes for ln in wrap(note, width, n, Level.WARNING)] for n in (3, 1)],
    ]
    # Giving way, in turn: a row per wheel; the blank lines; the errors that are not zero, in
    # two lines then one; the header, the bus and the notes in a line each; three frame IDs;
    # fewer motors; no frame IDs.
    motors, ids = 3, 5
    give_way = [motors, 2, 4, 6, 7, 7, 0, 1, 8, ids, *[motors] * len(sections[motors]), ids]
    lines = fit(sections, height, give_way)
    held = lines.count(_IDS)  # fewer than MIN_ID_ROWS when the terminal is too short
    if held:
        at = lines.index(_IDS)
        room = None if height is None else height - len(lines) + held
        lines[at:at + held] = _ids(snap, room, page, keys)[: room or None]
    return "\n".join(paint(line, width, colour) for line in lines)
