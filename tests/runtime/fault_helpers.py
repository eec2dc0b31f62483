"""The run, samples and checks shared by the fault-injection tests (test_faults_*).

Fault injection during a run: the daemon on simulated time with its device simulators.

Each test drives the robot forward (a twist from a socket client every 0.1 s), injects one
fault into one motor's simulator (:class:`gateway.sim.device.SimFault`) or into the gateway's edges,
checks the safe state and the error reported, clears the fault and checks the recovery.
Drivers: ODrive (the embedded default, four axes), VESC (``differential_tub``), DJI
(``mecanum``) and CiA 402 (``synchro``); loop at 100 Hz, ``enable_timeout_s`` 1 s.

================= ================================= ======================= =====================
fault             expected safe state               error reported          recovery
================= ================================= ======================= =====================
stops answering   FAULT, every wheel zero, within   FAULT reason and socket automatic once it
(``SILENT``)      ``liveness_s`` + 2 cycles; twists ``error`` event:        answers again
                  refused                           ``motor 'X' (node N)
                                                    stopped answering``
reports a fault   FAULT, every wheel zero (ODrive,  ``motor 'X' (node N)    automatic if the
(``FAULT``)       DJI, CiA 402).  VESC: RUNNING --  reports a fault:``      cause is gone by the
                  STATUS carries no fault; the VESC and the decoded flags   first retry (0.5 s);
                  releases the motor for 0.5 s and  (DRV_FAULT, temperature the re-enable clears
                  then follows again                110 degC, EMCY)         the latched error
late, 20 ms       RUNNING, the wheels follow        nothing                 nothing needed
(``LATE``)
late, liveness    FAULT, every wheel zero, within   ``... stopped           automatic, even while
+ 0.15 s          ``liveness_s`` + 2 cycles (the    answering``             still late: there are
(``LATE``)        gap before the first late frame)                          no timestamps, so a
                                                                            late stream counts
garbage           FAULT, every wheel zero, within   the motor named;        ``enable`` (recovery
(``GARBAGE``)     0.5 s (the real feedback is gone; rejected-frame counters ``manual``); with
                  valid-length garbage may pass for grow                    ``auto`` the loop
                  feedback or read as a fault)                              must not raise
wheel does not    FAULT, every wheel zero, once the ``motor 'X' (node N) does automatic if the
follow (``STALL``) wheel was off its command for a   not follow its          wheel follows by the
                  net ``tracking_time_s`` (0.5 s)   command: ...``; code    first retry (0.5 s)
                                                    ``tracking_error``
late, 70 ms, DJI  FAULT (the host-side speed loop   ``... does not follow   (as above)
(``LATE``)        oscillates; tracking error); the  its command``
                  ESC gets zero current
drops every 2nd   RUNNING (DJI, CiA 402; ODrive     ``... stopped           automatic
frame (``DROP``)  unless two heartbeats in a row    answering``
                  are lost).  VESC: FAULT -- two
                  frames per period, so STATUS_5 is
                  always the one lost
the bus refuses   the loop goes on, counts, reopens ``send_failures``,      automatic once the
sends             the bus; drives fall back on      ``bus_reopens``;        bus takes frames
                  their own timeouts: ODrive        ODrive:
                  watchdog (FAULT), VESC releases;  ``WATCHDOG_TIMER_
                  DJI and CiA 402 (no RPDO timeout  EXPIRED``
                  set) hold the last command
client leaves     the half line is dropped, never   ``dropped_partial``     nothing needed
mid-line          acted on; the loop goes on        counter
1000 clients at   the loop keeps cycling and        ``refused`` counter     a fresh client is
once              following the twist; beyond                               served
                  ``max_clients`` connections are
                  closed at once; no fd leaks
================= ================================= ======================= =====================

Hazards found here and fixed since, each with its test in ``test_faults_*``: an enable refused
by an ODrive axis in an odd state raised out of ``Gateway.cycle``; DJI rejected-frame counters
grew a key per garbage value; a bus refusing after a reopen still read healthy; a DJI wheel whose
host-side speed loop goes unstable on late feedback (below ``liveness_s``) went undetected
(now the tracking-error check, :mod:`gateway.core.tracking`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import pytest

from gateway.core.types import GatewayState
from tests.conftest import CONFIG_DIR
from tests.e2e_helpers import Rig, SocketPilot, errors_on_can, virtual_config

if TYPE_CHECKING:
    from collections.abc import Iterator
    from pathlib import Path

    from gateway.drive.driver import MotorDriver
    from gateway.sim.device import DeviceSimulator, SimFault
    from gateway.wire.can import ErrorReport

#: Config per driver (``None``: the embedded default, four ODrive axes).
CONFIGS: dict[str, Path | None] = {
    "odrive": None,
    "vesc": CONFIG_DIR / "differential_tub.yaml",
    "dji": CONFIG_DIR / "mecanum.yaml",
    "cia402": CONFIG_DIR / "synchro.yaml",
}
DRIVERS = tuple(CONFIGS)
VX = 0.4  # m/s, forward: feasible for every robot here, and above the tub's VESC band
#: (its wheels below 0.27 m/s are not speed-controlled: factory s_pid_min_erpm 900)
RATE_HZ = 100.0
#: The motor the faults go into (the second one: not always the first in a frame).
VICTIM = 1


@dataclass(frozen=True, slots=True)
class Sample:
    """The gateway after one cycle at time ``t``."""

    t: float
    state: GatewayState
    speeds: tuple[float, ...]
    reason: str


class Run:
    """A rig with a socket client streaming a forward twist, recording every cycle."""

    def __init__(self, key: str, rig: Rig, pilot: SocketPilot) -> None:
        #: The driver under test (a key of CONFIGS).
        self.key = key
        self.rig = rig
        self.pilot = pilot
        self.streaming = True
        self._cycle = 0
        self._inbox: list[dict[str, object]] = []
        #: WG_Error frames seen on the bus (read every 10 cycles, which keeps the pilot's
        #: receive queue short: it gets a copy of every frame on the bus).
        self.can_errors: list[ErrorReport] = []

    @property
    def victim(self) -> DeviceSimulator:
        return self.rig.sims[VICTIM]

    @property
    def driver(self) -> MotorDriver[Any]:
        name = self.victim.motor.wheel
        return next(d for d, _ in self.rig.gw.drives.groups if any(
            m.wheel == name for m in d.motors))

    @property
    def state(self) -> GatewayState:
        return self.rig.gw.state

    def drive(self, seconds: float) -> list[Sample]:
        """Run ``seconds``, re-sending the twist every 10 cycles; one sample per cycle."""
        rig, out = self.rig, []
        for _ in range(round(seconds * RATE_HZ)):
            if self._cycle % 10 == 0:
                self.can_errors += errors_on_can(rig)
                if self.streaming:
                    self.pilot.send(op="twist", vx=VX)
            self._cycle += 1
            t = rig.t
            rig.advance(rig.period)
            out.append(Sample(t, rig.gw.state, rig.gw.prev.wheel_rad_s,
                              rig.gw.supervisor.reason))
        self._inbox += self.pilot.messages()  # keep the socket buffer short
        self.can_errors += errors_on_can(rig)
        return out

    def messages(self) -> list[dict[str, object]]:
        """What the pilot received since the last call."""
        out, self._inbox = self._inbox + self.pilot.messages(), []
        return out

    def until(self, state: GatewayState, within_s: float) -> Sample:
        """Drive until ``state``; fail after ``within_s``."""
        for sample in self.drive_iter(within_s):
            if sample.state is state:
                return sample
        raise AssertionError(f"no {state.name} within {within_s} s; now {self.state.name}: "
                             f"{self.rig.gw.supervisor.reason}")

    def drive_iter(self, seconds: float) -> Iterator[Sample]:
        for _ in range(round(seconds * RATE_HZ)):
            yield from self.drive(1.0 / RATE_HZ)

    def inject(self, fault: SimFault) -> float:
        """Inject ``fault`` into the victim; the time of injection."""
        self.victim.inject(fault)
        return self.rig.t

    def rejected(self) -> int:
        return sum(self.driver.rejected.values())

    def following(self) -> bool:
        """Whether every wheel turns at the commanded speed (ground truth, 2 %)."""
        target = self.rig.config.model.ik(self.rig.gw.prev.twist).wheel_rad_s
        truth = [s.wheel_velocity_rad_s for s in self.rig.drive_sims]
        return self.state is GatewayState.RUNNING and min(target) > 0.0 and all(
            abs(v - w) <= 0.02 * abs(w) for v, w in zip(truth, target, strict=True))


@pytest.fixture
def run(request: pytest.FixtureRequest, channel: str, sock_path: str) -> Iterator[Run]:
    """``request.param``: a driver name, or (driver name, loop options)."""
    param = request.param
    driver, loop = (param, {}) if isinstance(param, str) else param
    cfg = virtual_config(CONFIGS[driver], channel, rate_hz=RATE_HZ, enable_timeout_s=1.0,
                         **loop)
    with Rig(cfg, sock_path) as rig:
        rig.enable()
        pilot = SocketPilot(sock_path)
        try:
            r = Run(driver, rig, pilot)
            r.drive(1.0)
            assert r.following(), "the robot did not get up to speed"
            yield r
        finally:
            pilot.close()


def reaction_bound(r: Run) -> float:
    """The longest a silent motor may go unnoticed: liveness + 2 cycles."""
    return r.driver.live.liveness_s + 2 * r.rig.period + 1e-9


def assert_safe_from(samples: list[Sample], start: Sample) -> None:
    """From ``start`` on, every cycle is FAULT with every wheel at zero."""
    after = [s for s in samples if s.t >= start.t]
    assert after, "no samples after the fault"
    for s in after:
        assert s.state is GatewayState.FAULT, s
        assert all(v == 0.0 for v in s.speeds), s


def victim_text(r: Run) -> str:
    m = r.victim.motor
    return f"motor {m.wheel!r} (node {m.node_id})"
