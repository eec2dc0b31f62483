"""The bus-load budget against the bus: what each driver declares (and the gateway's own
frames) is what the gateway and the simulated controllers put on the bus.

Python-can's virtual bus has no bitrate, so no simulated run notices a configuration the real
bus cannot carry; the budget (:mod:`gateway.drive.traffic`) is the check, and this test keeps
it honest.  A robot runs for a few simulated seconds after its enable, driving; every frame
that reaches the bus is counted by a listener (the pilot's bus), the simulators' own by their
bus's ``send``, and the gateway's are the rest.  Per sender and frame shape (DLC, identifier
type, remote), the frames a second must match the budget's streams, and the bits a second
its load.  The simulators start from the devices' factory settings (an ODrive's estimates
every 10 ms, a DJI ESC's feedback every 1 ms), so a driver that declared another rate than the
device's, or forgot a stream, fails here.
"""

from __future__ import annotations

import collections
from pathlib import Path
from typing import TYPE_CHECKING

import pytest
import yaml

from gateway.bus.can_bus import drain
from gateway.config.budget import bus_budget
from gateway.core.types import Twist
from gateway.drive.traffic import Sender
from gateway.wire.busload import frame_bits
from tests.e2e_helpers import Rig, virtual_config

if TYPE_CHECKING:
    import can

    from gateway.drive.traffic import BusBudget

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / "config"

#: How long the bus is counted (s of simulated time).
WINDOW_S = 3.0

Shape = tuple[int, bool, bool]  # (DLC on the wire, extended, remote)


def _shape(dlc: int, extended: bool, remote: bool) -> Shape:
    return (0 if remote else dlc, extended, remote)


def _declared(budget: BusBudget) -> dict[tuple[Sender, Shape], float]:
    out: dict[tuple[Sender, Shape], float] = collections.defaultdict(float)
    for s in budget.streams:
        out[s.sender, _shape(s.dlc, s.extended, s.remote)] += s.per_s
    return dict(out)


def _measure(config_name: str | Path | None, channel: str, monkeypatch: pytest.MonkeyPatch,
             twist: Twist) -> tuple[dict[tuple[Sender, Shape], float], BusBudget, float]:
    """Frames a second per (sender, shape) on the bus, the budget, and the bits a second."""
    path = None if config_name is None else CONFIG / config_name
    cfg = virtual_config(path, channel)
    with Rig(cfg) as rig:
        budget = bus_budget(cfg, rig.gw.drives)
        rig.enable()
        by_sims: collections.Counter[Shape] = collections.Counter()
        send = rig.ctl.bus.send

        def counted(msg: can.Message, timeout: float | None = None) -> None:
            by_sims[_shape(msg.dlc, msg.is_extended_id, msg.is_remote_frame)] += 1
            send(msg, timeout)

        pilot = rig.pilot

        def drive(r: Rig) -> None:  # a twist every cycle, so none goes stale
            r.send_can_twist(twist)

        rig.advance(0.5, drive)  # (up to speed; the enable's exchanges are over)
        drain(pilot)
        monkeypatch.setattr(rig.ctl.bus, "send", counted)
        rig.advance(WINDOW_S, drive)
        seen = collections.Counter(_shape(f.dlc, f.is_extended_id, f.is_remote_frame)
                                   for f in drain(pilot, limit=1_000_000))
    rates: dict[tuple[Sender, Shape], float] = {}
    for shape, n in seen.items():
        sims = by_sims[shape]
        for sender, count in ((Sender.CONTROLLERS, sims), (Sender.GATEWAY, n - sims)):
            if count:
                rates[sender, shape] = count / WINDOW_S
    bits = sum(n * frame_bits(dlc, ext) for (dlc, ext, _), n in seen.items()) / WINDOW_S
    return rates, budget, bits


def _check(measured: dict[tuple[Sender, Shape], float], budget: BusBudget, bits: float) -> None:
    declared = _declared(budget)
    assert set(measured) == set(declared), (measured, declared)
    for key, per_s in declared.items():
        # A device's timer may fall on either side of the window's edges: one frame per
        # stream source; else within 2 %.
        assert measured[key] == pytest.approx(per_s, rel=0.02, abs=10.0 / WINDOW_S), key
    assert bits == pytest.approx(budget.load() / 100.0 * budget.bitrate, rel=0.02)


@pytest.mark.parametrize(("config_name", "twist"), [
    (None, Twist(0.4, 0.1, 0.3)),                      # ODrive, the embedded default
    ("skid_steer.yaml", Twist(0.5, 0.0, 0.4)),          # VESC
    ("synchro.yaml", Twist(0.3, 0.2, 0.0)),             # CiA 402, drive and steering
    ("mecanum.yaml", Twist(0.5, 0.2, 0.3)),             # DJI, feedback at 1 kHz
    ("example_dbc.yaml", Twist(0.4, 0.0, 0.3)),         # DBC, cycle times from the file
    ("ackermann.yaml", Twist(0.5, 0.0, 0.2)),           # VESC drive, ODrive steering
    ("swerve.yaml", Twist(0.3, 0.2, 0.2)),              # ODrive drive and steering, 500k
])
def test_the_budget_is_what_reaches_the_bus(
    config_name: str | None, twist: Twist, channel: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    _check(*_measure(config_name, channel, monkeypatch, twist))


def test_stated_odrive_rates_and_rtr_requests(
    channel: str, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    # ODrives whose heartbeat and estimates were set to 50 ms and 20 ms, one of them asked
    # for its estimates with a remote frame every cycle (and its cyclic ones off): the budget
    # counts what the blocks state, the simulators built from them send it.
    raw = yaml.safe_load((REPO / "gateway" / "data" / "default.yaml").read_text())
    raw["motor_defaults"].update(heartbeat_msg_rate_ms=50, encoder_msg_rate_ms=20)
    raw["motors"]["rear_right"].update(encoder_request="rtr", encoder_msg_rate_ms=0)
    path = tmp_path / "stated.yaml"
    path.write_text(yaml.safe_dump(raw))
    measured, budget, bits = _measure(path, channel, monkeypatch, Twist(0.4, 0.1, 0.3))
    assert [(s.name, s.sender.value, s.per_s, s.remote) for s in budget.streams[1:4]] == [
        ("Heartbeat", "controllers", 80.0, False),
        ("Get_Encoder_Estimates", "controllers", 150.0, False),
        ("Get_Encoder_Estimates", "gateway", 200.0, True)]
    _check(measured, budget, bits)
