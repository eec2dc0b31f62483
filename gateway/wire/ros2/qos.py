"""The QoS chunk of rmw_zenoh's liveliness tokens: ``qos_to_keyexpr`` and ``keyexpr_to_qos``.

From ``rmw_zenoh_cpp/src/detail/liveliness_utils.cpp`` and ``qos.cpp`` in the public repository
ros2/rmw_zenoh (and ``docs/design.md``, "Graph Cache").  The chunk is six ``:``-separated
parts, some split by ``,``::

    <reliability>:<durability>:<history>,<depth>:<deadline s>,<deadline ns>:
    <lifespan s>,<lifespan ns>:<liveliness>,<lease s>,<lease ns>      (one line, no spaces)

Each value is the decimal ``rmw_qos_*_policy_e`` number (``rmw/types.h``, ros2/rmw), and is
left **empty when it equals rmw_zenoh's default**: reliable, volatile, keep-last, depth 42,
infinite deadline, lifespan and lease, automatic liveliness.  A reliable, volatile,
keep-last-10 endpoint is therefore ``::,10:,:,:,,`` (the examples of ``design.md`` show
exactly that).  Before rmw_zenoh pull request #266 (August 2024) every value was written out;
:func:`parse_qos_chunk` reads both.  System-default values are first replaced by rmw_zenoh's
defaults and a depth of 0 by 42, as ``QoS::best_available_qos`` does.  Pure: no I/O.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from gateway.core.errors import DecodeError, EncodeError


class Reliability(enum.IntEnum):
    """``rmw_qos_reliability_policy_e``."""

    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2


class Durability(enum.IntEnum):
    """``rmw_qos_durability_policy_e``."""

    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2


class History(enum.IntEnum):
    """``rmw_qos_history_policy_e``."""

    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2


#: rmw_zenoh's depth for a depth of 0 (``RMW_ZENOH_DEFAULT_HISTORY_DEPTH``).
DEFAULT_DEPTH = 42
_DEFAULT_RELIABILITY = Reliability.RELIABLE
_DEFAULT_DURABILITY = Durability.VOLATILE
_DEFAULT_HISTORY = History.KEEP_LAST
_ENTITY = "rmw_zenoh QoS chunk"
_U32_MAX = 2**32 - 1


@dataclass(frozen=True, slots=True)
class QosProfile:
    """The QoS settings a token carries that the bridge uses.

    Deadline, lifespan and liveliness are always rmw_zenoh's defaults when built here, and
    checked but not kept when parsed.

    :param reliability: delivery guarantee.
    :param durability: whether late joiners get past samples.
    :param history: keep-last or keep-all.
    :param depth: samples kept with keep-last.
    """

    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    history: History = History.KEEP_LAST
    depth: int = 10


def _adapted(profile: QosProfile) -> QosProfile:
    """``profile`` after ``QoS::best_available_qos``: system defaults made explicit."""
    return QosProfile(
        _DEFAULT_RELIABILITY if profile.reliability == Reliability.SYSTEM_DEFAULT
        else profile.reliability,
        _DEFAULT_DURABILITY if profile.durability == Durability.SYSTEM_DEFAULT
        else profile.durability,
        _DEFAULT_HISTORY if profile.history == History.SYSTEM_DEFAULT else profile.history,
        DEFAULT_DEPTH if profile.depth == 0 else profile.depth,
    )


def qos_chunk(reliability: Reliability = Reliability.RELIABLE,
              durability: Durability = Durability.VOLATILE,
              history: History = History.KEEP_LAST,
              depth: int = 10) -> str:
    """The QoS chunk rmw_zenoh writes in the token of an endpoint with these settings.

    :raises EncodeError: a value that is not one of the enums, or a depth outside ``uint32``.

    >>> qos_chunk(Reliability.RELIABLE, Durability.VOLATILE, History.KEEP_LAST, 10)
    '::,10:,:,:,,'
    >>> qos_chunk(Reliability.BEST_EFFORT, Durability.TRANSIENT_LOCAL, History.KEEP_LAST, 1)
    '2:1:,1:,:,:,,'
    """
    for value, kind in ((reliability, Reliability), (durability, Durability),
                        (history, History)):
        if not isinstance(value, kind):
            raise EncodeError(f"{_ENTITY}: expected a {kind.__name__}, got {value!r}")
    if isinstance(depth, bool) or not isinstance(depth, int) or not 0 <= depth <= _U32_MAX:
        raise EncodeError(f"{_ENTITY}: expected a depth from 0 to {_U32_MAX}, got {depth!r}")
    q = _adapted(QosProfile(reliability, durability, history, depth))

    def part(value: int, default: int) -> str:
        return "" if value == default else str(value)

    return (
        f"{part(q.reliability, _DEFAULT_RELIABILITY)}:"
        f"{part(q.durability, _DEFAULT_DURABILITY)}:"
        f"{part(q.history, _DEFAULT_HISTORY)},{part(q.depth, DEFAULT_DEPTH)}"
        ":,:,:,,"
    )


def _number(text: str, what: str, chunk: str) -> int | None:
    """The decimal ``text`` (``None`` when empty)."""
    if text == "":
        return None
    if not text.isascii() or not text.isdigit() or len(text) > 20:
        raise DecodeError(f"{_ENTITY}: expected a decimal number for {what}, got {text!r} "
                          f"in {chunk!r}")
    return int(text)


def _enum(kind: type[enum.IntEnum], text: str, default: int, chunk: str) -> int:
    value = _number(text, kind.__name__.lower(), chunk)
    if value is None:
        return default
    try:
        return kind(value)
    except ValueError:
        valid = ", ".join(f"{m.value} ({m.name})" for m in kind)
        raise DecodeError(f"{_ENTITY}: expected a {kind.__name__.lower()} of {valid}, "
                          f"got {value} in {chunk!r}") from None


def parse_qos_chunk(chunk: str) -> QosProfile:
    """The :class:`QosProfile` of a token's QoS chunk (empty parts are rmw_zenoh's defaults).

    :raises DecodeError: not six parts, wrong sub-parts, or a value that is not a number
        or not a known policy.

    >>> parse_qos_chunk("2:1:,1:,:,:,,")  # doctest: +NORMALIZE_WHITESPACE
    QosProfile(reliability=<Reliability.BEST_EFFORT: 2>,
               durability=<Durability.TRANSIENT_LOCAL: 1>, history=<History.KEEP_LAST: 1>,
               depth=1)
    """
    parts = chunk.split(":")
    if len(parts) != 6:
        raise DecodeError(f"{_ENTITY}: expected 6 parts separated by ':', got {len(parts)} "
                          f"in {chunk!r}")
    subparts = [p.split(",") for p in parts[2:]]
    sizes = [len(s) for s in subparts]
    if sizes != [2, 2, 2, 3]:
        raise DecodeError(f"{_ENTITY}: expected history,depth:deadline s,ns:lifespan s,ns:"
                          f"liveliness,lease s,ns, got {chunk!r}")
    reliability = _enum(Reliability, parts[0], _DEFAULT_RELIABILITY, chunk)
    durability = _enum(Durability, parts[1], _DEFAULT_DURABILITY, chunk)
    history = _enum(History, subparts[0][0], _DEFAULT_HISTORY, chunk)
    depth = _number(subparts[0][1], "depth", chunk)
    for text in (*subparts[1], *subparts[2], *subparts[3]):
        _number(text, "a duration or the liveliness", chunk)
    return _adapted(QosProfile(
        Reliability(reliability), Durability(durability), History(history),
        DEFAULT_DEPTH if depth is None else depth,
    ))
