"""The gateway's reports keep their configured rates (``odom_rate_hz``, ``status_rate_hz``):
each is due one period after its last due time, not after the cycle that sent it, so cycles
that come a hair early or late do not stretch every period; after a stall, no burst."""

from __future__ import annotations

import collections
import random

import pytest

from gateway.config import load_config
from gateway.runtime.loop import Gateway


def _reports(channel: str, times: list[float]) -> dict[str, int]:
    gw = Gateway(load_config(None, {"interface": "virtual", "channel": channel}))
    try:
        ids = gw.wg.ids
        out: collections.Counter[int] = collections.Counter()
        for t in times:
            out.update(f.arbitration_id for f in gw.publisher.publish(t, None, False)
                       if f.arbitration_id in (ids.odom_pose, ids.status))
        return {"pose": out[ids.odom_pose], "status": out[ids.status]}
    finally:
        gw.close()


@pytest.mark.parametrize("rate_hz", [200.0, 1000.0])
def test_jittered_cycles_keep_the_rates(channel: str, rate_hz: float) -> None:
    # Cycles on their grid, each up to 20 us early or late (a fixed pseudo-random draw), for
    # 10 s from t = 1000 s.
    period = 1.0 / rate_hz
    jitter = random.Random(7)
    times = [1000.0 + k * period + jitter.uniform(-2e-5, 2e-5)
             for k in range(round(10.0 * rate_hz))]
    got = _reports(channel, times)
    assert got["pose"] == pytest.approx(500, abs=1)  # odom_rate_hz 50
    assert got["status"] == pytest.approx(100, abs=1)  # status_rate_hz 10


def test_a_stall_gives_one_report_not_a_burst(channel: str) -> None:
    times = [1000.0 + k * 0.005 for k in range(10)] + [1002.0 + k * 0.005 for k in range(4)]
    # 0.045 s: 3 odometry reports (0, 20, 40 ms); after the 2 s stall one, then the next is
    # 20 ms later (beyond the 15 ms that follow).
    assert _reports(channel, times)["pose"] == 4
