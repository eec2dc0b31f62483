"""Text screens that fit the terminal: lines with a colour, wrapping, fitting to a height, and
the steering actuators beside their wheels.  Shared by the ``jog`` and ``monitor`` screens.

Pure: the caller says how wide and tall the terminal is and whether to colour; nothing here
reads the environment or writes to a terminal.

* A :class:`Line` is plain text and, for a fault or a warning, the column where its colour
  starts; :func:`paint` cuts it to the width first, so an escape code never counts as a
  column and never overflows a line.  Faults and errors are red, warnings yellow (SGR 31 and
  33), only where :func:`wants_colour` says so: on a terminal, unless ``NO_COLOR`` is set to
  a non-empty value (https://no-color.org).
* :func:`fit` chooses, section by section, the richest rendering that leaves the whole within
  the height: each section offers renderings from the fullest to the leanest, and the screen
  says in which order they give way.
* :func:`pair_steering` puts a steering actuator that turns one wheel beside that wheel, so a
  condensed screen shows one line per wheel with its speed and its steering angle.
"""

from __future__ import annotations

import enum
import textwrap
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from gateway.core.settings import GatewayConfig

__all__ = [
    "CUT",
    "Level",
    "Line",
    "cut",
    "fit",
    "pack",
    "paint",
    "pair_steering",
    "steering_of",
    "wants_colour",
    "wrap",
]


class Level(enum.Enum):
    """How a line (from its :attr:`Line.start`) is shown; the value is its SGR colour code."""

    PLAIN = ""
    WARNING = "33"
    ERROR = "31"


@dataclass(frozen=True, slots=True)
class Line:
    """One line of a screen.

    :param text: the text, without escape codes.
    :param level: its colour from column ``start`` on.
    :param start: the first coloured column (0: the whole line).
    """

    text: str
    level: Level = Level.PLAIN
    start: int = 0


def wants_colour(isatty: bool, environ: Mapping[str, str]) -> bool:
    """Whether to colour: on a terminal, and ``NO_COLOR`` unset or empty (https://no-color.org:
    "when present and not an empty string, prevents the addition of ANSI color")."""
    return isatty and not environ.get("NO_COLOR")


#: Ends a text cut short (a name too long for its column, a line too long for the screen).
CUT = "~"


def cut(text: str, width: int) -> str:
    """``text`` in at most ``width`` columns, its last one :data:`CUT` when it is cut."""
    return text if len(text) <= width else text[:max(width - 1, 0)] + CUT[:width]


def paint(line: Line, width: int, colour: bool) -> str:
    """``line`` :func:`cut` to ``width`` columns, then coloured (when ``colour``)."""
    text = cut(line.text, width)
    if not colour or line.level is Level.PLAIN or line.start >= len(text):
        return text
    return f"{text[:line.start]}\x1b[{line.level.value}m{text[line.start:]}\x1b[0m"


def wrap(text: str, width: int, max_lines: int, level: Level = Level.PLAIN,
         start: int = 0) -> list[Line]:
    """``text`` in lines of at most ``width`` columns (continuations indented by 4), the last
    one ending in ``[...]`` when it does not fit in ``max_lines``; coloured from ``start`` on
    the first line, wholly on the others."""
    lines = textwrap.wrap(text, max(width, 8), subsequent_indent="    ",
                          max_lines=max(max_lines, 1)) or [""]
    return [Line(t, level, start if i == 0 else 0) for i, t in enumerate(lines)]


def pack(parts: Sequence[str], width: int, max_lines: int, level: Level = Level.PLAIN,
         start: int = 0, sep: str = "  ") -> list[Line]:
    """``parts`` joined by ``sep`` in lines of at most ``width`` columns, a part never split
    across lines (continuations indented by 4, the last one ending in ``[...]`` when they do
    not fit in ``max_lines``); coloured as :func:`wrap` colours."""
    more = " [...]"
    rows: list[list[str]] = []
    cut = False
    for part in parts:
        room = width - (4 if len(rows) > 1 else 0)  # of the last line; continuations indent
        if rows and len(sep.join([*rows[-1], part])) <= room:
            rows[-1].append(part)
        elif len(rows) >= max(max_lines, 1):  # no line left: leave parts out, and say so
            while len(rows[-1]) > 1 and len(sep.join(rows[-1]) + more) > room:
                rows[-1].pop()
            cut = True
            break
        else:
            rows.append([part])
    lines = [("    " if i else "") + sep.join(row) for i, row in enumerate(rows)]
    # A separator such as ", " keeps its comma at the end of a line that goes on.
    lines = [t + sep.rstrip() for t in lines[:-1]] + lines[-1:]
    if cut:
        lines[-1] = lines[-1][: max(width - len(more), 0)] + more
    return [Line(t, level, start if i == 0 else 0) for i, t in enumerate(lines)]


def fit(sections: Sequence[Sequence[Sequence[Line]]], height: int | None,
        give_way: Sequence[int]) -> list[Line]:
    """The screen's lines, at most ``height`` of them (``None``: no limit).

    :param sections: per section, its renderings from the fullest to the leanest (an empty
        rendering leaves the section out).
    :param height: the rows available.
    :param give_way: section indices: while the lines do not fit, each step takes the next
        leaner rendering of the section it names (a section named twice gives way twice).
    :return: the chosen renderings, in section order, cut to ``height`` as a last resort.
    """
    choice = [0] * len(sections)

    def rows() -> int:
        return sum(len(s[c]) for s, c in zip(sections, choice, strict=True))

    if height is not None:
        for i in give_way:
            if rows() <= height:
                break
            choice[i] = min(choice[i] + 1, len(sections[i]) - 1)
    lines = [ln for s, c in zip(sections, choice, strict=True) for ln in s[c]]
    return lines if height is None else lines[: max(height, 0)]


def pair_steering(names: Sequence[str], steers: Mapping[str, Sequence[str]]
                  ) -> list[tuple[int, int | None]]:
    """The motors in screen order, a steering actuator beside the wheel it turns.

    :param names: every motor's name, in status order (the drive motors, then the actuators).
    :param steers: per steering actuator's name, the wheels it turns.
    :return: (index of a motor, index of the actuator that turns that wheel alone, or
        ``None``); an actuator of several wheels (a linkage, a steer group) or of a wheel not
        listed stands on its own, after the wheels.
    """
    index = {name: i for i, name in enumerate(names)}
    beside: dict[int, int] = {}
    for name, wheels in steers.items():
        if name in index and len(wheels) == 1 and wheels[0] in index:
            beside.setdefault(index[wheels[0]], index[name])
    placed = set(beside.values())
    rows: list[tuple[int, int | None]] = [
        (i, beside.get(i)) for i, name in enumerate(names) if name not in steers]
    rows += [(i, None) for i, name in enumerate(names) if name in steers and i not in placed]
    return rows


def steering_of(config: GatewayConfig) -> dict[str, tuple[str, ...]]:
    """Per steering actuator of ``config`` (by the name its status carries), the wheels it
    turns."""
    return {a.wheel: a.steers for a in config.steering}
