"""The driver contract's template (:mod:`gateway.drive.driver`), on a minimal protocol.

``Toy`` implements only the hooks, as a third-party driver would: one command frame per motor
(ID ``0x100 + node``, int16 speed in 0.01 rad/s), one feedback frame (``0x180 + node``: int32
position in mrad, int16 speed) and a status frame (``0x200 + node``) as a second liveness stream.
Everything else -- the checks of the setpoints, malformed-frame counting, liveness, faults,
protection, dispatch by claims -- is the base's, and is what these tests check.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import pytest
from hypothesis import given
from hypothesis import strategies as st

from gateway.core.errors import ConfigError, DecodeError, DriverNotFoundError, EncodeError
from gateway.core.protection import Guard, ProtectionState, WatchdogPolicy
from gateway.core.types import DriveFault, DriveState, Frame, MotorConfig, WheelFeedback
from gateway.drive.claims import FrameClaim, FrameRouter
from gateway.drive.driver import MotorDriver
from gateway.drive.filters import EXT_MASK, STD_MASK
from gateway.drive.options import StatedTimeout, option
from gateway.sim.registry import simulator_for
from tests import factories

if TYPE_CHECKING:
    from collections.abc import Sequence


@dataclass(frozen=True, kw_only=True)
class ToyOptions(StatedTimeout):
    """The toy's keys: the common ones and a bus-wide bitrate."""

    bitrate: int = option(int, 500_000, choices=(250_000, 500_000), help="bus bitrate")


class Toy(MotorDriver[ToyOptions]):
    """A protocol with only the hooks implemented."""

    Options = ToyOptions
    BUS_WIDE: ClassVar[tuple[str, ...]] = ("liveness_s", "bitrate")
    LIVENESS_STREAMS: ClassVar[tuple[str, ...]] = ("feedback", "status")
    PROTOCOL: ClassVar[str] = "Toy"
    CONFIGURES_PROTECTION: ClassVar[bool] = True

    def __init__(self, motors: Sequence[MotorConfig]) -> None:
        super().__init__(motors)
        self.setup = [ProtectionState.PENDING] * len(self.motors)

    def _command(self, setpoints: Sequence[float], now_s: float) -> list[Frame]:
        return [
            Frame(0x100 + m.node_id, struct.pack("<h", round(w * 100 * s)))
            for m, w, s in zip(self.motors, setpoints, self.motor_scale, strict=True)
        ]

    def _on_frame(self, frame: Frame) -> bool:
        i = self.index_of(frame.arbitration_id & 0x7F)
        if i is None:
            return False
        kind = frame.arbitration_id & ~0x7F
        if kind == 0x180:
            if frame.dlc != 6:
                raise DecodeError(f"Expected 6 bytes in Toy feedback, but got {frame.dlc}.")
            pos, vel = struct.unpack("<ih", frame.data)
            self.store_feedback(i, WheelFeedback(pos / 1000, vel / 100, frame.timestamp_s))
        elif kind == 0x200:
            self.live.heard(i, 1, frame.timestamp_s)
            self.set_armed(i, bool(frame.data[0]))
        return True

    def _enable(self, now_s: float) -> list[Frame]:
        return [Frame(0x000, bytes([1, m.node_id])) for m in self.motors]

    def disable(self, now_s: float) -> list[Frame]:
        return [Frame(0x000, bytes([2, m.node_id])) for m in self.motors]

    def claims(self) -> tuple[FrameClaim, ...]:
        out = [FrameClaim.exact(0x000, False, None, receive=False)]
        for i, m in enumerate(self.motors):
            out += [FrameClaim.exact(0x100 + m.node_id, False, i, receive=False),
                    FrameClaim.exact(0x180 + m.node_id, False, i),
                    FrameClaim.exact(0x200 + m.node_id, False, i)]
        return tuple(out)

    def protection_state(self, index: int) -> ProtectionState:
        return self.setup[index]

    def protection_failure(self, index: int) -> str:
        return "the controller answered 0"


def toy_motor(node: int, wheel: str = "left", **options: object) -> MotorConfig:
    return factories.motor("toy", node, wheel, gear_ratio=2.0, max_rpm=600.0, driver_class=Toy,
                           options=options)


def toy(*nodes: int) -> Toy:
    return Toy([toy_motor(n, f"w{n}") for n in nodes])


# ----------------------------------------------------------------------------- options


def test_options_are_a_typed_dataclass_with_the_common_keys_declared_once() -> None:
    drv = Toy([toy_motor(1, controller_timeout_s=0.5, liveness_s=0.1)])
    assert drv.opts[0] == ToyOptions(liveness_s=0.1, controller_timeout_s=0.5, bitrate=500_000)
    assert list(Toy.OPTIONS) == ["liveness_s", "controller_timeout_s", "bitrate"]
    assert drv.live.liveness_s == 0.1


@pytest.mark.parametrize(("block", "message"), [
    ({"bitrat": 1}, "motor 'left'.bitrat: unknown key; did you mean 'bitrate'? (known protocol "
                    "keys for this driver: bitrate, controller_timeout_s, liveness_s)"),
    ({"bitrate": 125_000}, "motor 'left'.bitrate: expected one of 250000, 500000, got 125000"),
    ({"liveness_s": 0.0}, "motor 'left'.liveness_s: expected at least 0.001, got 0.0"),
    ({"controller_timeout_s": "1"}, "motor 'left'.controller_timeout_s: expected float, got '1'"),
])
def test_bad_options_name_the_key_what_was_expected_and_what_came(
    block: dict[str, object], message: str
) -> None:
    with pytest.raises(ConfigError) as info:
        toy_motor(1, "left", **block)
    assert str(info.value) == message


def test_bus_wide_keys_must_agree() -> None:
    with pytest.raises(ConfigError, match=r"motor 'b'\.bitrate: expected 500000 like motor 'a' "
                                          r"on the same Toy bus, got 250000"):
        Toy([toy_motor(1, "a"), toy_motor(2, "b", bitrate=250_000)])


def test_node_ids_are_checked_by_the_base() -> None:
    with pytest.raises(ConfigError, match=r"node 1 is already used by wheel 'a'"):
        Toy([toy_motor(1, "a"), toy_motor(1, "b")])
    with pytest.raises(ConfigError, match=r"expected int 0\.\.63, got 64"):
        Toy([toy_motor(64)])


# ----------------------------------------------------------------------------- command


def test_command_encodes_checked_setpoints_through_the_hook() -> None:
    assert toy(1, 2).command([1.0, -0.5], 0.0) == [
        Frame(0x101, struct.pack("<h", 200)), Frame(0x102, struct.pack("<h", -100))]


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, 31.5])
def test_a_bad_setpoint_is_refused_with_the_wheel_node_and_bounds(bad: float) -> None:
    # max_rpm 600 at the motor, gear 2: 300 rpm at the wheel = 31.416 rad/s.
    drv = toy(1, 2)
    with pytest.raises(EncodeError) as info:
        drv.command([0.0, bad], 0.0)
    assert str(info.value) == (
        f'Expected a wheel speed for Toy node 2 ("w2") between -31.4159 and 31.4159 rad/s '
        f"(max_rpm 600), but got {bad}.")


def test_the_wrong_number_of_setpoints_is_refused() -> None:
    with pytest.raises(EncodeError, match=r"Expected 2 setpoints for the Toy motors \(w1, w2\), "
                                          r"but got 1\."):
        toy(1, 2).command([0.0], 0.0)


@given(st.floats(allow_nan=True, allow_infinity=True))
def test_every_setpoint_is_encoded_or_refused_never_passed_on_unchecked(value: float) -> None:
    drv = toy(1)
    limit = drv.motors[0].max_wheel_rad_s
    if math.isfinite(value) and abs(value) <= limit:
        assert len(drv.command([value], 0.0)) == 1
    else:
        with pytest.raises(EncodeError):
            drv.command([value], 0.0)


# ----------------------------------------------------------------------------- receive


def test_a_malformed_frame_is_counted_never_raised() -> None:
    drv = toy(1)
    assert drv.on_frame(Frame(0x181, bytes(5))) is True
    assert drv.rejected == {"malformed": 1}
    assert drv.last_rejection["malformed"] == "Expected 6 bytes in Toy feedback, but got 5."
    assert drv.on_frame(Frame(0x185, bytes(6))) is False  # not our node


def test_a_motor_is_offline_until_every_liveness_stream_is_young() -> None:
    drv = toy(1)
    assert drv.state(0, 0.0) is DriveState.OFFLINE
    drv.on_frame(Frame(0x181, struct.pack("<ih", 1000, 50), timestamp_s=1.0))
    assert drv.state(0, 1.0) is DriveState.OFFLINE  # no status yet
    assert drv.live.silent(0, 1.0) == ["status"]
    drv.on_frame(Frame(0x201, bytes([1]), timestamp_s=1.1))
    assert drv.state(0, 1.1) is DriveState.ENABLED
    assert drv.feedback(0) == WheelFeedback(1.0, 0.5, 1.0)
    # The feedback stream goes silent: OFFLINE after liveness_s (0.25 s) of it.
    assert drv.state(0, 1.25) is DriveState.ENABLED
    assert drv.state(0, 1.26) is DriveState.OFFLINE
    assert drv.live.silent(0, 1.26) == ["feedback"]


def test_each_motor_goes_offline_after_its_own_liveness() -> None:
    class Loose(Toy):  # liveness_s per motor, as VESC, CiA 402 and DBC take it
        BUS_WIDE: ClassVar[tuple[str, ...]] = ("bitrate",)

    drv = Loose([toy_motor(1, "w1"), toy_motor(2, "w2", liveness_s=1.0)])
    for node in (1, 2):
        drv.on_frame(Frame(0x180 + node, bytes(6), timestamp_s=0.0))
        drv.on_frame(Frame(0x200 + node, bytes([1]), timestamp_s=0.0))
    assert drv.states(0.5) == [DriveState.OFFLINE, DriveState.ENABLED]
    assert [drv.state(i, 0.5) for i in (0, 1)] == drv.states(0.5)
    assert drv.live.liveness_s == 1.0  # the longest
    assert drv.states(1.01) == [DriveState.OFFLINE, DriveState.OFFLINE]


def test_faults_come_before_the_ready_state() -> None:
    drv = toy(1)
    drv.on_frame(Frame(0x181, bytes(6), timestamp_s=0.0))
    drv.on_frame(Frame(0x201, bytes([1]), timestamp_s=0.0))
    drv.set_fault(0, DriveFault.OVER_CURRENT, "overcurrent")
    assert drv.state(0, 0.0) is DriveState.FAULT
    assert drv.status(0.0)[0].detail == "overcurrent"


# ----------------------------------------------------------------------------- protection


def test_a_failed_protection_is_reported_once_per_enable_and_blocks_arming() -> None:
    drv = toy(1)
    drv.enable(0.0)
    assert not drv.may_arm(0)  # pending
    drv.setup[0] = ProtectionState.FAILED
    drv.poll(0.1)
    drv.poll(0.2)
    assert drv.faults(0) == DriveFault.WATCHDOG
    assert drv.detail(0) == ("motor 'w1' (Toy node 1): controller watchdog not confirmed: the "
                             "controller answered 0; fix: " + Toy.TIMEOUT_FIX)
    assert not drv.may_arm(0)
    # The controller's own healthy report does not clear it; a new enable does.
    drv.set_fault(0, DriveFault.NONE)
    assert drv.faults(0) == DriveFault.WATCHDOG
    drv.setup[0] = ProtectionState.CONFIRMED
    drv.enable(1.0)
    assert drv.faults(0) == DriveFault.NONE
    assert drv.may_arm(0)


def test_under_warn_a_failed_protection_arms_with_a_warning(
    caplog: pytest.LogCaptureFixture,
) -> None:
    drv = toy(1)
    drv.watchdog_policy = WatchdogPolicy.WARN
    drv.enable(0.0)
    drv.setup[0] = ProtectionState.FAILED
    drv.poll(0.1)
    assert drv.faults(0) == DriveFault.NONE
    assert drv.may_arm(0)
    assert "arming it anyway" in caplog.text


def test_the_stated_timeout_is_the_default_protection() -> None:
    assert toy(1).protection(0).guard is Guard.UNSTATED
    assert Toy([toy_motor(1, controller_timeout_s=0.5)]).protection(0).guard is Guard.STATED


# ----------------------------------------------------------------------------- claims


def test_claims_give_the_receive_filters_and_the_dispatch() -> None:
    a, b = toy(1, 2), Toy([toy_motor(5, "w5")])
    assert [str(f) for f in a.receive_filters()] == [
        "181/7FF", "201/7FF", "182/7FF", "202/7FF"]
    router = FrameRouter([(a, a.claims()), (b, b.claims())])
    assert router.owner(0x182, False) is a
    assert router.owner(0x205, False) is b
    assert router.owner(0x102, False) is None  # a command: sent, not taken
    assert router.owner(0x182, True) is None  # another identifier type


@given(st.integers(0, 0x7FF), st.integers(0, 0x7FF), st.booleans())
def test_a_masked_claim_matches_exactly_the_identifiers_it_expands_to(
    can_id: int, mask: int, extended: bool
) -> None:
    high = EXT_MASK & ~STD_MASK if extended else 0  # the bits above 11 must be 0
    claim = FrameClaim(can_id, mask | 0x780 | high, extended)  # at most 7 open bits
    ids = claim.identifiers()
    assert ids is not None
    assert sorted(ids) == [i for i in range(0x800) if claim.matches(i, extended)]


def test_a_wide_claim_is_matched_after_the_lookup() -> None:
    wide = FrameClaim(0x1000_0000, 0x1000_0000, True)  # 28 open bits: not expanded
    assert wide.identifiers() is None
    router: FrameRouter[str] = FrameRouter([("exact", [FrameClaim.exact(0x1000_0001, True)]),
                                            ("wide", [wide])])
    assert router.owner(0x1000_0001, True) == "exact"
    assert router.owner(0x1234_5678, True) == "wide"
    assert router.owner(0x0234_5678, True) is None


def test_a_driver_must_declare_its_frames() -> None:
    class Silent(Toy):
        claims = MotorDriver.claims

    with pytest.raises(TypeError, match="claims"):
        Silent([toy_motor(1)])


# ----------------------------------------------------------------------------- simulators


def test_a_driver_without_a_simulator_is_named_when_one_is_asked_for() -> None:
    with pytest.raises(DriverNotFoundError, match=r"No simulator for driver 'toy': --sim and the "
                                                  r"tests need one registered in the "
                                                  r"'gateway.simulators' entry-point group"):
        simulator_for(toy_motor(1))
