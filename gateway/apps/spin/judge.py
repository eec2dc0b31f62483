"""The verdict of ``wheelgate spin``, pure: the encoder's measurement against the command (the
controller), what the operator saw against the measurement (the configuration).

Rules, in order; each that holds adds a :class:`Finding` with its advice:

1. the controller faulted or fell silent during the spin: :attr:`Check.FAULT`; too little
   feedback to measure: :attr:`Check.NO_FEEDBACK`;
2. encoder against command, ``k = measured / commanded`` over the steady part:
   ``|k| < 0.1``: :attr:`Check.NO_MOTION`; ``k < 0``: :attr:`Check.CONTROLLER_REVERSED`;
   ``k`` outside ``1/1.25 .. 1.25``: :attr:`Check.CONTROLLER_SCALE`;
3. seen against encoder, ``r = seen / measured`` (a person's estimate, so a wider band): the
   wheel stood still (``r = 0``): :attr:`Check.NOT_SEEN`; else ``r < 0``:
   :attr:`Check.INVERT` (toggle ``invert``); ``|r|`` outside ``1/1.5 .. 1.5``:
   :attr:`Check.GEAR_RATIO` (``gear_ratio / |r|``: the wheel turned ``|r|`` times as far as
   the configuration says).

Only 3 can find a wrong ``invert`` or ``gear_ratio``: wheelgate converts the command and the
feedback through both, so the encoder agrees with the command whatever they are.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.apps.spin.plan import SpinPlan

#: Encoder against command: below this ratio the motor did not turn.
NO_MOTION_RATIO = 0.1
#: Encoder against command: the ratio within ``1/x .. x`` that agrees.
ENCODER_TOLERANCE = 1.25
#: Seen against encoder: the ratio within ``1/x .. x`` that agrees (a person's estimate).
SEEN_TOLERANCE = 1.5
#: The shortest steady stretch that is measured (s).
MIN_SPAN_S = 0.2
#: The exit status of a verdict with something to fix (0 agrees, 1 error or not checked,
#: 2 usage, 3 is ``twist``'s infeasible twist).
EXIT_FIX = 4


class Check(enum.Enum):
    """What a finding is about (its JSON name is the value)."""

    FAULT = "fault"
    NO_FEEDBACK = "no_feedback"
    NO_MOTION = "no_motion"
    CONTROLLER_REVERSED = "controller_reversed"
    CONTROLLER_SCALE = "controller_scale"
    NOT_SEEN = "not_seen"
    INVERT = "invert"
    GEAR_RATIO = "gear_ratio"


@dataclass(frozen=True, slots=True)
class Sample:
    """One feedback of the motor, as its driver decoded it.

    :param t_s: its receive time, from the start of the command (s).
    :param position_rad: the wheel's angle, or a steering actuator's steering angle (rad).
    :param velocity_rad_s: the wheel's speed, or the steering rate (rad/s).
    """

    t_s: float
    position_rad: float
    velocity_rad_s: float


@dataclass(frozen=True, slots=True)
class Measured:
    """What the encoder measured.

    :param value: the steady wheel speed (rad/s), or the sweep's held offset (rad).
    :param ratio: ``value`` over the commanded one.
    :param travel_rad: how far the wheel turned in all (a sweep: its largest offset), rad.
    """

    value: float
    ratio: float
    travel_rad: float


@dataclass(frozen=True, slots=True)
class Finding:
    """Something to fix.

    :param check: what it is about.
    :param advice: what was measured or seen, and what to do.
    """

    check: Check
    advice: str


@dataclass(frozen=True, slots=True)
class Verdict:
    """The outcome of one spin.

    :param plan: what was commanded.
    :param measured: the encoder's measurement (``None``: too little of it).
    :param seen: what the operator saw over what the encoder measured (``None``: not asked
        or not answered).
    :param findings: what to fix (none: the motor agrees).
    :param notes: what the findings do not say (what was not checked, an early stop).
    :param stopped_by: what stopped the spin early, if anything did.
    :param unchecked: why no one said what the wheel did (``--no-ask``, no answer), when the
        controller agrees: ``invert`` and ``gear_ratio`` were not checked.
    """

    plan: SpinPlan
    measured: Measured | None
    seen: float | None
    findings: tuple[Finding, ...]
    notes: tuple[str, ...] = ()
    stopped_by: str = ""
    unchecked: str = ""

    @property
    def ok(self) -> bool:
        """Whether sign and magnitude agree (nothing to fix)."""
        return not self.findings

    @property
    def judged(self) -> bool:
        """Whether there was anything to judge (an early stop may leave nothing)."""
        return self.measured is not None or bool(self.findings)

    def lines(self) -> list[str]:
        """The verdict for people: one line per finding, or one that it agrees."""
        name = self.plan.motor.wheel
        if not self.judged:
            return [f"{name}: nothing judged: {'; '.join(self.notes)}"]
        if self.findings:
            return [f"{name}: {f.advice}" for f in self.findings]
        m = self.measured
        if m is None:  # pragma: no cover - judged without findings has a measurement
            raise ValueError("a verdict without findings needs a measurement")
        said = (f"measured {_amount(self.plan, m.value)} for "
                f"{_amount(self.plan, self.plan.commanded)}")
        if self.seen is None:
            why = f" ({self.unchecked})" if self.unchecked else ""
            return [f"{name}: the controller agrees: {said}; invert and gear_ratio were not "
                    f"checked by a person{why}"]
        return [f"{name}: agrees: {said}, and the wheel did as described"]

    def as_json(self, exit_status: int) -> dict[str, Any]:
        """The verdict as a JSON object (``wheelgate spin --json``), for the command's
        ``exit_status`` (:func:`exit_status`): ``"ok"`` is whether it is 0 -- the motor agrees
        and was checked as asked -- while ``"findings"`` say what to fix, ``"judged"``
        whether anything was measured and ``"config_checked"`` whether a person checked
        invert and gear_ratio."""
        m, plan = self.measured, self.plan
        return {
            "motor": plan.motor.wheel, "driver": plan.motor.driver,
            "node_id": plan.motor.node_id, "role": "steer" if plan.steering else "drive",
            "commanded": plan.commanded, "unit": "rad" if plan.steering else "rad/s",
            "duration_s": plan.duration_s,
            "measured": None if m is None else {"value": m.value, "ratio": m.ratio,
                                                "travel_rad": m.travel_rad},
            "seen_ratio": self.seen, "ok": exit_status == 0, "judged": self.judged,
            "findings": [{"check": f.check.value, "advice": f.advice} for f in self.findings],
            "notes": list(self.notes), "stopped_by": self.stopped_by or None,
            "config_checked": self.seen is not None,
            "unchecked": (self.unchecked or None) if self.seen is None else None,
        }


def exit_status(verdict: Verdict, signalled: int = 0) -> int:
    """The exit status of ``wheelgate spin`` for ``verdict``: ``signalled`` (128 + the signal
    that stopped it, 0: none) first; 1 when nothing was judged, or when the controller agrees
    but no person checked invert and gear_ratio without ``--no-ask`` saying so; else 0 when
    the motor agrees, :data:`EXIT_FIX` when there is something to fix."""
    if signalled:
        return signalled
    if not verdict.judged:
        return 1
    if verdict.ok and verdict.seen is None and verdict.unchecked != "--no-ask":
        return 1
    return 0 if verdict.ok else EXIT_FIX


def measure(plan: SpinPlan, samples: Sequence[Sample], until_s: float = math.inf
            ) -> Measured | None:
    """The encoder's measurement over the steady part of the command (ending at ``until_s``
    when the spin stopped early); ``None`` when less than :data:`MIN_SPAN_S` of it has
    feedback.

    A wheel's speed is its turn over the time between the first and last sample (an encoder's
    position, not its noisy speed); a sweep's offset is the mean held angle from the origin.
    """
    start, end = plan.window
    end = min(end, until_s)
    inside = [s for s in samples if start <= s.t_s <= end]
    if len(inside) < 2 or inside[-1].t_s - inside[0].t_s < MIN_SPAN_S:
        return None
    if plan.steering:
        value = sum(s.position_rad for s in inside) / len(inside) - plan.origin_rad
        travel = max((s.position_rad - plan.origin_rad for s in samples), key=abs)
    else:
        value = ((inside[-1].position_rad - inside[0].position_rad)
                 / (inside[-1].t_s - inside[0].t_s))
        travel = samples[-1].position_rad - samples[0].position_rad
    return Measured(value, value / plan.commanded, travel)


def described(plan: SpinPlan, measured: Measured) -> float:
    """The amount the operator is told the wheel turned, as the encoder measured it: turns of
    a wheel, degrees of a sweep (a magnitude; its direction is said in words)."""
    travel = abs(measured.travel_rad)
    return math.degrees(travel) if plan.steering else travel / math.tau


def parse_seen(text: str, amount: float) -> float | None:
    """What the operator saw, over what the encoder measured (:func:`described`: ``amount``).

    Enter, ``y`` or ``f``: as described (1); ``r`` or ``b``: the other way (-1); ``n``: it did
    not turn (0); ``s`` or ``?``: not seen (``None``); a number: the turns (degrees of a sweep)
    seen, negative the other way; ``4x``: four times as far (``-4x``: the other way).

    >>> parse_seen("", 0.5), parse_seen("r", 0.5), parse_seen("-0.25", 0.5), parse_seen("10x", 0.5)
    (1.0, -1.0, -0.5, 10.0)

    :raises ValueError: for anything else, saying what is expected.
    """
    word = text.strip().lower()
    words = {"": 1.0, "y": 1.0, "yes": 1.0, "f": 1.0, "ok": 1.0, "r": -1.0, "b": -1.0,
             "reverse": -1.0, "n": 0.0, "no": 0.0, "none": 0.0}
    if word in words:
        return words[word]
    if word in ("s", "skip", "?"):
        return None
    factor = word.endswith("x")
    try:
        number = float(word[:-1] if factor else word)
    except ValueError:
        number = math.nan
    if not math.isfinite(number) or (not factor and amount <= 0.0):
        raise ValueError(f"expected Enter (as described), r (the other way), n (it did not "
                         f"turn), s (not seen), the amount seen (e.g. -0.5) or a factor "
                         f"(e.g. 4x); got {text.strip()!r}")
    return number if factor else number / amount


def judge(plan: SpinPlan, measured: Measured | None, seen: float | None, fault: str = "",
          stopped_by: str = "", unchecked: str = "") -> Verdict:
    """The verdict (the rules are in the module's doc).

    :param measured: :func:`measure` of the spin.
    :param seen: :func:`parse_seen` of the operator's answer (``None``: none).
    :param fault: the controller's fault, or its silence, that ended the spin early.
    :param stopped_by: the key or signal that stopped the spin early.
    :param unchecked: why there is no answer (``seen`` is ``None``), for the verdict's words.
    """
    m = plan.motor
    node = f"the {m.driver} controller of {m.wheel} (node {m.node_id})"
    findings: list[Finding] = []
    notes: list[str] = [f"stopped early by {stopped_by}"] if stopped_by else []
    if fault:
        findings.append(Finding(Check.FAULT, f"{node} stopped during the spin: {fault}; fix "
                                             f"that first"))
    if measured is None:
        if not fault and not stopped_by:
            findings.append(Finding(Check.NO_FEEDBACK, (
                f"too little feedback from {node} to measure its motion: check its feedback "
                f"rate and the bus (wiring, bitrate, termination)")))
        elif stopped_by:
            notes.append("the motion was not measured")
        return Verdict(plan, None, seen, tuple(findings), tuple(notes), stopped_by, unchecked)
    k = measured.ratio
    said = (f"measured {_amount(plan, measured.value)} for "
            f"{_amount(plan, plan.commanded)}")
    if abs(k) < NO_MOTION_RATIO:
        findings.append(Finding(Check.NO_MOTION, (
            f"{said}: it did not turn although {node} was armed; check that nothing blocks "
            f"it, its brake, the motor's phase wiring and the controller's current limit")))
    elif k < 0:
        findings.append(Finding(Check.CONTROLLER_REVERSED, (
            f"{said}: {node} turns against its own command (its encoder counts the other way "
            f"than its motor turns); fix that on the controller: invert cannot, it turns "
            f"command and feedback together")))
    elif not 1 / ENCODER_TOLERANCE <= k <= ENCODER_TOLERANCE:
        why = ("check its speed and current limits, its tuning and that the wheel turns freely"
               if k < 1 else "check its own units (pole pairs, encoder counts) and its tuning")
        findings.append(Finding(Check.CONTROLLER_SCALE, (
            f"{said} ({k:.2g}x): {node} does not follow its command; {why}; if its encoder "
            f"sits on the wheel, not the motor: gear_ratio {m.gear_ratio:g} would be "
            f"{m.gear_ratio / k:.4g}")))
    if seen is not None and abs(k) >= NO_MOTION_RATIO:
        findings.extend(_seen_findings(plan, measured, seen))
    elif seen is None and not findings:
        notes.append("invert and gear_ratio were not checked: the encoder sees the motor "
                     "through them; watch the wheel and answer the question to check them")
    return Verdict(plan, measured, seen, tuple(findings), tuple(notes), stopped_by, unchecked)


def _seen_findings(plan: SpinPlan, measured: Measured, seen: float) -> list[Finding]:
    m = plan.motor
    if seen == 0.0:
        return [Finding(Check.NOT_SEEN, (
            f"the encoder measured {_amount(plan, measured.travel_rad, travel=True)} but the "
            f"wheel was seen standing still: the motor turns without it (a slipping coupling or "
            f"gearbox), or node {m.node_id} is another wheel's motor: check node_id of "
            f"{m.wheel} (if it turned a little, answer how far: gear_ratio may be far too "
            f"small)"))]
    out = []
    value = seen * measured.value
    said = f"seen {_amount(plan, value)} for {_amount(plan, plan.commanded)}"
    if seen < 0:
        out.append(Finding(Check.INVERT, f"{said}: set invert: {str(not m.invert).lower()} "
                                         f"on {m.wheel}"))
    if not 1 / SEEN_TOLERANCE <= abs(seen) <= SEEN_TOLERANCE:
        out.append(Finding(Check.GEAR_RATIO, (
            f"{said} ({abs(seen):.2g}x the command): check gear_ratio on {m.wheel}: "
            f"{m.gear_ratio:g} would be about {m.gear_ratio / abs(seen):.3g}")))
    return out


def _amount(plan: SpinPlan, value: float, travel: bool = False) -> str:
    """A speed (rad/s), a sweep's angle (deg) or a wheel's turn (turns), signed."""
    if plan.steering:
        return f"{math.degrees(value):+.1f} deg"
    if travel:
        return f"{value / math.tau:+.2f} turns"
    return f"{value:+.2f} rad/s"
