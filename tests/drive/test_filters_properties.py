"""The identifiers each driver declares it takes (``receive_filters``), by property: what they
let through must be everything the driver would take (nothing it needs is dropped) and nothing
else (foreign traffic stays out).

Checked for every driver of every shipped configuration (and an ODrive robot on 29-bit
identifiers, which none ships): the frames its simulators send while it enables and drives
them, an exhaustive sweep of the identifiers a driver could take (every 11-bit ID, the 29-bit
IDs below 0x10000 where the VESC and small ODrive nodes live, every ID a filter passes, and the
neighbours of every ID on the wire), random frames with random payloads, and the simulator of
a node that is not configured.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import TYPE_CHECKING, Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivers.vesc.appconf import HOST_ID as VESC_HOST_ID
from gateway.bus.can_bus import drain
from gateway.core.types import Frame, MotorConfig, Twist
from gateway.drive.driveset import DriveSet
from gateway.drive.filters import EXT_MASK, STD_MASK, CanFilter, matches_any
from gateway.sim.registry import simulator_for
from tests.conftest import CONFIG_DIR
from tests.drive.filter_helpers import ODRIVE_EXTENDED, Ident, config, declared, drivers
from tests.e2e_helpers import Rig, virtual_config

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable, Sequence

    from gateway.drive.driver import MotorDriver
CONFIGS: list[str | None] = [
    None, *sorted(p.name for p in CONFIG_DIR.glob("*.yaml")), ODRIVE_EXTENDED
]


# ----------------------------------------------------------------------------- the wire


def setpoints(motors: Sequence[MotorConfig]) -> list[float]:
    """A wheel speed for each drive motor (rad/s) and a steering angle for each actuator."""
    return [0.1 if m.steering else 2.0 for m in motors]


def converse(driver: type[MotorDriver[Any]], motors: tuple[MotorConfig, ...], seconds: float = 0.4,
             step_s: float = 0.001) -> tuple[list[Frame], list[Frame]]:
    """A fresh driver of ``motors`` and their simulators talking, without a bus: the enable
    sequence, then commands every 10 ms, the simulators stepped every ``step_s`` (DJI ESCs
    report every millisecond).

    :return: the frames the simulators sent, and the frames the driver sent.
    """
    drv = driver(motors)
    sims = [simulator_for(m) for m in motors]
    from_sims: list[Frame] = []
    from_driver: list[Frame] = []
    out = drv.enable(0.0)
    for k in range(round(seconds / step_s)):
        t = k * step_s
        from_driver.extend(out)
        replies = [r for f in out for sim in sims for r in sim.handle(f, t)]
        replies += [r for sim in sims for r in sim.tick(t)]
        from_sims.extend(replies)
        for r in replies:
            drv.on_frame(r.stamped(t))
        out = drv.poll(t)
        if k % 10 == 0:
            out += drv.command(setpoints(motors), t)
    return from_sims, from_driver


@functools.cache
def wire(name: str | None) -> tuple[tuple[tuple[Ident, ...], tuple[Ident, ...]], ...]:
    """Per driver of configuration ``name``: the identifiers its simulators sent, and those
    it sent (:func:`converse`)."""
    out = []
    for drv in drivers(name):
        from_sims, from_driver = converse(type(drv), drv.motors)
        out.append((tuple(sorted({(f.arbitration_id, f.is_extended_id) for f in from_sims})),
                    tuple(sorted({(f.arbitration_id, f.is_extended_id) for f in from_driver}))))
    return tuple(out)


# ----------------------------------------------------------------------------- the sweep


def span(f: CanFilter) -> list[Ident]:
    """Every identifier ``f`` passes (its free bits enumerated; a filter is expected to leave
    at most 12 free)."""
    full = EXT_MASK if f.extended else STD_MASK
    free = [b for b in range(full.bit_length()) if not f.can_mask >> b & 1]
    assert len(free) <= 12, f"filter {f} passes {2 ** len(free)} identifiers"
    base = f.can_id & f.can_mask & full
    out = []
    for k in range(1 << len(free)):
        ident = base
        for j, b in enumerate(free):
            if k >> j & 1:
                ident |= 1 << b
        out.append((ident, f.extended))
    return out


def neighbours(ident: Ident) -> set[Ident]:
    """Identifiers one bit, or the low byte, away from ``ident`` (same type)."""
    can_id, ext = ident
    width = 29 if ext else 11
    out = {(can_id ^ 1 << b, ext) for b in range(width)}
    out |= {((can_id & ~0xFF) | k, ext) for k in range(256)}
    return out


@functools.cache
def universe(name: str | None, k: int) -> frozenset[Ident]:
    """The identifiers swept for driver ``k`` of ``name`` (see the module docstring)."""
    out: set[Ident] = {(i, False) for i in range(STD_MASK + 1)}
    out |= {(i, True) for i in range(0x10000)}
    for f in declared(drivers(name)[k]):
        out.update(span(f))
    for ident in (*wire(name)[k][0], *wire(name)[k][1]):
        out |= neighbours(ident)
    return frozenset(out)


def payloads(motors: Sequence[MotorConfig]) -> list[tuple[bytes, bool]]:
    """(data, remote) probes: a remote frame, empty and 8-byte data, and a payload that
    starts with each node ID (a VESC PONG names the answering controller there)."""
    return [(b"", True), (b"", False), (bytes(8), False),
            *((bytes([m.node_id & 0xFF]), False) for m in motors)]


@functools.cache
def prober(name: str | None, k: int) -> Callable[[Ident], bool]:
    """Whether driver ``k`` of ``name`` takes a frame on an identifier, with some probe
    payload (one driver for every probe: it is stateful, but whether a frame is its own is
    not)."""
    drv = drivers(name)[k]
    probes = [(data, remote, 0 if remote else len(data)) for data, remote in payloads(drv.motors)]
    take = drv.on_frame

    def probe(ident: Ident) -> bool:
        can_id, ext = ident
        return any(take(Frame(can_id, data, ext, remote, dlc)) for data, remote, dlc in probes)

    return probe


@functools.cache
def claimed(name: str | None, k: int) -> frozenset[Ident]:
    """The swept identifiers driver ``k`` of ``name`` takes."""
    return frozenset(filter(prober(name, k), universe(name, k)))


def passed(filters: Iterable[CanFilter]) -> set[Ident]:
    """Every identifier ``filters`` pass."""
    return set().union(*map(span, filters))


def exactness(name: str | None, k: int, filters: Sequence[CanFilter]
              ) -> tuple[set[Ident], set[Ident]]:
    """What driver ``k`` of ``name`` takes or its simulators send that ``filters`` drop (over
    the swept identifiers), and what they pass that the driver does not take.

    The spans of the filters are enumerated, so the second set is complete.
    """
    through = passed(filters)
    beyond = through - universe(name, k)
    wanted = {*claimed(name, k), *wire(name)[k][0], *filter(prober(name, k), beyond)}
    return wanted - through, through - wanted


CASES = [(name, k) for name in CONFIGS for k in range(len(drivers(name)))]


def case_id(case: tuple[str | None, int]) -> str:
    name, k = case
    return f"{name or 'default'}-{type(drivers(name)[k]).__name__}"


# ----------------------------------------------------------------------------- properties


@pytest.mark.parametrize("case", CASES, ids=case_id)
def test_the_filters_pass_exactly_what_the_driver_takes(case: tuple[str | None, int]) -> None:
    name, k = case
    drv = drivers(name)[k]
    dropped, extra = exactness(name, k, declared(drv))
    assert not dropped, f"frames the driver takes that its filters drop: {sorted(dropped)[:8]}"
    assert not extra, f"frames its filters pass that it does not take: {sorted(extra)[:8]}"


@pytest.mark.parametrize("case", CASES, ids=case_id)
def test_what_the_simulators_send_passes_the_filters(case: tuple[str | None, int]) -> None:
    name, k = case
    filters = declared(drivers(name)[k])
    from_sims, _ = wire(name)[k]
    assert from_sims  # the simulators did talk
    assert [i for i in from_sims if not matches_any(filters, *i)] == []


@pytest.mark.parametrize("case", CASES, ids=case_id)
def test_the_simulator_of_a_node_not_configured_is_kept_out(case: tuple[str | None, int]
                                                            ) -> None:
    name, k = case
    drv = drivers(name)[k]
    lo, hi = type(drv).node_id_range(drv.motors[0].options)
    used = {m.node_id for m in drv.motors}
    node = next(n for n in (max(used) + 1, *range(lo, hi + 1)) if lo <= n <= hi
                and n not in used)
    model = next((m for m in drv.motors if not m.steering), drv.motors[0])
    stranger = dataclasses.replace(model, node_id=node, wheel="stranger")
    from_stranger, _ = converse(type(drv), (stranger,))
    assert from_stranger
    filters = declared(drv)
    # (A VESC's buffer replies, its app configuration asked for by the driver, go to the
    # gateway's own ID and name no sender: any VESC's pass, and the read checks the
    # controller_id inside, drivers.vesc.readback.)
    replies = {(p << 8 | VESC_HOST_ID, True) for p in (5, 6, 7, 8)}
    leaks = {(f.arbitration_id, f.is_extended_id) for f in from_stranger
             if matches_any(filters, f.arbitration_id, f.is_extended_id)} - replies
    assert not leaks, f"node {node}'s frames pass: {sorted(leaks)}"


@pytest.mark.parametrize("case", CASES, ids=case_id)
def test_every_filter_is_needed_and_a_broken_declaration_is_caught(
    case: tuple[str | None, int]
) -> None:
    """No declared filter is redundant, and the checks above fail for a declaration with a
    filter dropped or with its mask one bit off (unless that leaves the same identifiers
    passing, as merging two neighbouring nodes' ranges can)."""
    name, k = case
    filters = declared(drivers(name)[k])
    assert len(set(filters)) == len(filters)
    for i, f in enumerate(filters):
        fewer = filters[:i] + filters[i + 1:]
        assert exactness(name, k, fewer)[0], f"dropping {f} is not noticed"
        full = EXT_MASK if f.extended else STD_MASK
        for b in range(full.bit_length()):
            mutant = (*fewer, dataclasses.replace(f, can_mask=f.can_mask ^ 1 << b))
            if passed(mutant) != passed(filters):
                assert any(exactness(name, k, mutant)), f"mask bit {b} of {f} flipped"


@pytest.mark.parametrize("name", CONFIGS)
# The draws depend on the configuration (st.data); on a loaded machine generating them can
# trip the too_slow health check, which says nothing about the drivers.
@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_every_random_frame_a_driver_takes_passes_its_filters(
    name: str | None, data: st.DataObject
) -> None:
    ds = DriveSet(config(name))
    seen = [i for sims, sent in wire(name) for i in (*sims, *sent)]
    nodes = [m.node_id & 0xFF for drv, _ in ds.groups for m in drv.motors]
    ident = data.draw(st.one_of(
        st.tuples(st.integers(0, STD_MASK), st.just(False)),
        st.tuples(st.integers(0, EXT_MASK), st.just(True)),
        st.tuples(st.integers(0, 0xFFFF), st.just(True)),
        st.tuples(st.sampled_from(seen), st.integers(0, EXT_MASK)).map(
            lambda t: ((t[0][0] ^ t[1]) & (EXT_MASK if t[0][1] else STD_MASK), t[0][1])),
        st.tuples(st.sampled_from(seen), st.integers(0, 28)).map(
            lambda t: ((t[0][0] ^ 1 << t[1]) & (EXT_MASK if t[0][1] else STD_MASK), t[0][1])),
    ), label="identifier")
    payload = data.draw(st.one_of(
        st.binary(max_size=8),
        st.tuples(st.sampled_from(nodes), st.binary(max_size=7)).map(
            lambda t: bytes([t[0]]) + t[1]),
    ), label="payload")
    remote = data.draw(st.booleans(), label="remote")
    frame = Frame(ident[0], b"" if remote else payload, ident[1], remote,
                  len(payload))
    for drv, _ in ds.groups:
        if drv.on_frame(frame):
            assert matches_any(declared(drv), *ident), (type(drv).__name__, frame)
    filters = ds.receive_filters()
    assert filters is not None
    if DriveSet(config(name)).on_frame(frame):
        assert matches_any(filters, *ident)


@pytest.mark.parametrize("name", CONFIGS)
def test_what_the_simulated_controllers_send_on_a_bus_passes_the_gateways_filters(
    name: str | None, channel: str
) -> None:
    """The whole gateway on a virtual bus: enabled, driven, every frame of the devices (what
    the pilot saw besides the gateway's own) passes :attr:`Gateway.receive_filters`."""
    path = None if name is None else CONFIG_DIR / name
    if name == ODRIVE_EXTENDED:
        pytest.skip("made in memory; the sweep and the simulators cover it")
    cfg = virtual_config(path, channel, rate_hz=100.0)
    with Rig(cfg) as rig:
        rig.enable()
        rig.send_can_twist(Twist(0.1))
        rig.advance(0.5)
        filters = rig.gw.receive_filters
        assert filters is not None
        sent_by_gateway = {(i, e) for (i, e, tx) in rig.gw.edge.id_counts if tx}
        from_devices = {(f.arbitration_id, f.is_extended_id) for f in drain(rig.pilot)
                        } - sent_by_gateway
        assert from_devices  # the devices did talk
        for can_id, extended in from_devices:
            assert matches_any(filters, can_id, extended), (hex(can_id), extended, filters)
