"""The ablation of a cycle (tools/cycle_ablation.py) removes what it says: every part it replaces
is work the gateway's cycle does on the benchmark's frames, each no-op takes effect and goes
again at the end of its block, the gateway still runs without them (the measurement's own
check), and the table's arithmetic is the difference it describes."""

from __future__ import annotations

import functools
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from gateway.core.types import GatewayState

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))

import cycle_ablation
from cycle_ablation import CHECKS, PARTS, Part, Variant, removed, report
from throughput_instructions import ANCHOR, MIXES, Row
from throughput_rig import Bench

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator


@pytest.fixture
def bench() -> Iterator[Bench]:
    """The DJI robot of the throughput benchmark, enabled and driving (a short pool)."""
    b = Bench("dji", overhead_ns=0.0)
    b.record_pool(0.05, enable_cycles=450, twist_cycles=50)
    yield b
    b.close()


def _run(bench: Bench, cycles: int) -> None:
    bench.run_gateway(bench.schedule(MIXES[0], cycles), None)


def test_removed_puts_each_no_op_in_place_and_then_the_original_back() -> None:
    originals = {n: p.owner.__dict__[p.method] for n, p in PARTS.items()}
    with removed(PARTS):
        for p in PARTS.values():
            assert p.owner.__dict__[p.method] is p.replacement
    with pytest.raises(RuntimeError), removed(["tallies", "residual"]):
        raise RuntimeError
    for n, p in PARTS.items():
        assert p.owner.__dict__[p.method] is originals[n]
    with pytest.raises(KeyError), removed(["nothing"]):
        pass


def test_every_part_is_work_the_cycle_does(bench: Bench, monkeypatch: pytest.MonkeyPatch) -> None:
    calls = dict.fromkeys(PARTS, 0)

    def counting(name: str, original: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(original)
        def spy(*args: Any, **kwargs: Any) -> Any:
            calls[name] += 1
            return original(*args, **kwargs)
        return spy

    spies = {n: Part(p.what, p.owner, p.method, counting(n, p.owner.__dict__[p.method]))
             for n, p in PARTS.items()}
    monkeypatch.setattr(cycle_ablation, "PARTS", spies)
    with removed(spies):
        _run(bench, 20)
    # Every cycle runs each (liveness once per feedback frame, tallies for what is received
    # and what is sent); a part the cycle no longer calls would be measured as free.
    assert all(n >= 20 for n in calls.values()), calls
    assert calls["liveness"] >= 4 * 20


def test_without_every_part_the_gateway_runs_and_the_parts_are_gone(bench: Bench) -> None:
    gw = bench.gw
    rejected, tallies = bench.rejected(), gw.edge.id_counts
    distance = gw.odometry.state.distance_m
    with removed(PARTS):
        _run(bench, 50)
        assert gw.edge.counts.frames_received > 0
    assert gw.state is GatewayState.RUNNING and bench.rejected() == rejected
    assert gw.edge.id_counts == tallies  # no frame tallied
    assert gw.odometry.state.distance_m == distance  # no odometry sample taken
    _run(bench, 20)
    assert gw.edge.id_counts != tallies and gw.odometry.state.distance_m > distance


def _row(mix: str, gateway: float, pcan: float, anchor: float | None = None) -> Row:
    per_cycle = {"gateway": gateway + 10.0, "python-can": pcan + 10.0, "harness": 10.0}
    if anchor is not None:
        per_cycle[ANCHOR] = anchor + 10.0
    return Row("dji", mix, 1.0, 4.0, per_cycle, {})


def test_the_table_is_the_difference_and_the_ratio() -> None:
    base = Variant((), [_row(m, 300.0, 100.0, 180.0) for m in MIXES])
    one = Variant(("tallies",), [_row(m, 280.0, 101.0) for m in MIXES])
    bare = Variant(CHECKS, [_row(m, 250.0, 100.0) for m in MIXES])
    lines = report("dji", 200, [base, one, bare])
    assert lines[0].startswith("== dji: instructions per cycle (200 cycles")
    assert "python-can alone 100 (1 kHz mix)" in lines[0]
    assert lines[2].startswith("as it is") and lines[2].count("3.00x") == 2
    assert lines[3].startswith("without tallies") and "      280       20   2.77x" in lines[3]
    assert lines[4].startswith("without all the checks and tallies")
    assert lines[5].startswith("hand-written loop") and "180" in lines[5] and "1.80x" in lines[5]
    # 2x python-can alone (200) less what the checks cost (50) leaves 150; the loop needs 180
    assert lines[6] == ("1 kHz mix: without its checks and tallies the gateway is 1.39x the "
                        "hand-written loop; 2x python-can alone (200) less what they cost (50) "
                        "leaves 150 for the rest, which the hand-written loop does in 180")
