"""The bytecode map of a cycle (tools/cycle_bytecodes.py) counts what it says: every bytecode
once as some function's own, inclusive counts that add up along the calls (a recursion once),
and python-can's share as the code python-can runs, not what the caller runs beside it."""

from __future__ import annotations

import copy
import sys
from pathlib import Path

import can

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))

from cycle_bytecodes import Tracer, measure, report


def _leaf(x: int) -> int:
    return x * 2 + 1


def _middle(x: int) -> int:
    return _leaf(x) + _leaf(x + 1)


def _countdown(n: int) -> int:
    return 0 if n == 0 else 1 + _countdown(n - 1)


def _key(fn: object) -> str:
    code = fn.__code__  # type: ignore[attr-defined]
    return (f"{Path(code.co_filename).relative_to(Path(__file__).resolve().parents[2])}:"
            f"{code.co_firstlineno} {getattr(code, 'co_qualname', code.co_name)}")


def test_inclusive_counts_add_up_along_the_calls() -> None:
    tracer = Tracer()
    tracer.run(_middle, 3)
    c = tracer.counts
    middle, leaf = _key(_middle), _key(_leaf)
    assert c.calls[middle] == 1 and c.calls[leaf] == 2
    assert c.own[leaf] > 0 and c.own[middle] > 0
    assert c.inclusive[leaf] == c.own[leaf]
    assert c.inclusive[middle] == c.own[middle] + c.own[leaf]
    assert c.total == sum(c.own.values()) == c.inclusive[middle]
    assert c.python_can == 0


def test_a_recursion_counts_its_bytecodes_once() -> None:
    tracer = Tracer()
    tracer.run(_countdown, 5)
    c = tracer.counts
    key = _key(_countdown)
    assert c.calls[key] == 6
    assert c.inclusive[key] == c.own[key] == c.total


def test_python_can_share_is_what_python_can_runs_and_calls() -> None:
    msg = can.Message(arbitration_id=0x123, data=b"\x01\x02", is_extended_id=False)

    def build() -> None:
        can.Message(arbitration_id=0x123, data=b"\x01\x02", is_extended_id=False)

    def copies() -> None:
        copy.deepcopy(msg)  # the copy module, which calls python-can's __deepcopy__
        copy.copy([1, 2, 3])  # the copy module alone: not python-can's

    tracer = Tracer()
    tracer.run(build)
    c = tracer.counts
    assert c.python_can == c.total - c.own[_key(build)] > 0
    tracer = Tracer()
    tracer.run(copies)
    c = tracer.counts
    deep = next(k for k in c.calls if k.endswith(" Message.__deepcopy__"))
    # python-can's __deepcopy__ and the copy functions it calls back, nothing else
    assert c.python_can == c.inclusive[deep] > c.own[deep]
    assert c.total > c.python_can + c.own[_key(copies)]


def test_the_dji_report_splits_the_gateway_from_python_can() -> None:
    got = measure("dji", 20)
    text = report("dji", got, 20, 5)
    gw, pcan, harness = (got[s].total for s in ("gateway", "python-can", "harness"))
    assert gw > pcan > harness > 0
    # The gateway's python-can share is python-can alone's work (same frames), within the
    # few publish frames the two loops may differ by.
    share = got["gateway"].python_can / (pcan - harness)
    assert 0.9 < share < 1.1
    assert "ratio gateway / python-can alone" in text and "hand-written loop" in text
    assert "gateway/runtime/loop.py" in text and "tools/" not in text.split("-- ", 1)[1]
