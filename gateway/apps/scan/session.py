"""The course of one scan, pure: what was heard, what to ask next, and what it all shows.

:class:`ScanSession` is given every frame received (:meth:`~ScanSession.on_frame`) and asked
for the frames to send (:meth:`~ScanSession.poll`), both with the time, by the thin edge
(:mod:`gateway.apps.scan.scanner`); it never touches a bus or reads a clock.

1. **Listen** for the first quarter of the timeout (:class:`ScanTiming`): the periodic traffic
   (heartbeats, status, feedback) shows most controllers, and their protocols, before anything
   is sent.
2. **Ask**: the probes' discovery requests (a VESC PING per controller ID) and, for every
   controller found (again whenever a new identifier is heard), its probe's requests, one at a
   time per controller, each waiting for its answer up to :attr:`ScanTiming.answer_s`.  One
   frame goes out at most every :attr:`ScanTiming.spacing_s` (2 ms: a 29-bit PING every 2 ms
   is 4 % of a 1 Mbit/s bus, 15 % of a 250 kbit/s one), interviews before discovery.  A
   request whose identifier belongs to a controller of another protocol that was found, or to
   the gateway's own messages, or that another protocol's controllers all take (a DJI command,
   a CANopen NMT), or to a configured motor of another driver (its driver's declared frames,
   :func:`~gateway.apps.scan.own.motor_claims`), is not sent; the report says so.
3. **Report** at the timeout: the identifiers heard sorted into controllers
   (:func:`~gateway.apps.scan.classify.classify`), each described by its probe from what it
   sent and answered, the configured motors heard only on their declared identifiers (found
   by ``config``), then the gateway's own messages and the unknown identifiers.

Answers to the scan's requests are not counted as traffic (nor are late ones).
"""

from __future__ import annotations

import collections
import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.apps.scan.classify import Classified, Configured, Sighting, classify
from gateway.apps.scan.known import KnownMotors
from gateway.apps.scan.report import UNKNOWN, WHEELGATE, ScannedDevice, ScanReport
from gateway.core.types import hex_id
from gateway.drive.labels import DRIVER_TITLES
from gateway.drive.scan import Answer, Description, Heard

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from gateway.apps.scan.own import MotorClaims
    from gateway.core.types import Frame, MotorConfig
    from gateway.drive.scan import Request, ScanProbe

#: The shortest time between two frames the scan sends (s).
SPACING_S = 0.002
#: The shortest wait for an answer (s).
MIN_ANSWER_S = 0.25
#: What found a configured motor heard only on its declared identifiers.
CONFIGURED = "config"


@dataclass(frozen=True, slots=True)
class ScanTiming:
    """How long a scan listens, waits and paces (s).

    :param timeout_s: the whole scan.
    :param listen_s: listening only, at the start.
    :param answer_s: the longest wait for an answer to one request.
    :param spacing_s: the shortest time between two requests.
    """

    timeout_s: float
    listen_s: float
    answer_s: float
    spacing_s: float = SPACING_S

    @classmethod
    def for_timeout(cls, timeout_s: float) -> ScanTiming:
        """Listen a quarter of ``timeout_s``; wait for an answer a tenth of it, at least
        :data:`MIN_ANSWER_S`."""
        return cls(timeout_s, timeout_s / 4.0, max(MIN_ANSWER_S, timeout_s / 10.0))


@dataclass(slots=True)
class _Tally:
    """Frames on one identifier: how many, the latest data frame, when the first and the
    latest came."""

    count: int
    last: Frame | None
    first_s: float
    last_s: float


@dataclass(slots=True)
class _Out:
    """A request sent and not yet answered or given up."""

    probe: int
    request: Request
    sent_s: float
    interview: tuple[int, int, bool] | None
    done: bool = False


@dataclass(slots=True)
class _Interview:
    """The requests of one controller found: those still to send, the answers, the notes."""

    queue: collections.deque[Request]
    waiting: bool = False
    answers: list[Answer] = dataclasses.field(default_factory=list)
    notes: list[str] = dataclasses.field(default_factory=list)


class ScanSession:
    """One scan (see the module's doc).

    :param probes: the protocols' probes, in precedence order.
    :param timing: how long to listen, wait and pace.
    :param start_s: when the scan starts (monotonic s).
    :param own_ids: ``(identifier, extended)`` -> name of the gateway's own messages.
    :param known: the configuration's motors: a controller found with a motor's driver, node
        ID and identifier type (from ``claimed``) is reported with its wheel; a motor whose
        controller was not found is named in the report's notes
        (:class:`~gateway.apps.scan.known.KnownMotors`).
    :param claimed: the configured motors' declared identifiers (see the module).
    """

    def __init__(self, probes: Sequence[ScanProbe], timing: ScanTiming, start_s: float,
                 own_ids: Mapping[tuple[int, bool], str] | None = None,
                 known: Sequence[MotorConfig] = (),
                 claimed: Sequence[MotorClaims] = ()) -> None:
        self.probes = tuple(probes)
        self.timing = timing
        self.start_s = start_s
        self.own_ids = dict(own_ids or {})
        self.known = KnownMotors(known, claimed)
        self.claimed = tuple(claimed)
        #: Frames sent.
        self.requests_sent = 0
        self._tally: dict[tuple[int, bool], _Tally] = {}
        self._by_answer: dict[tuple[int, bool], list[_Out]] = {}
        self._outstanding: collections.deque[_Out] = collections.deque()
        self._interviews: dict[tuple[int, int, bool], _Interview] = {}
        self._order: list[tuple[int, int, bool]] = []
        self._turn = 0
        self._discovery: collections.deque[tuple[int, Request]] = collections.deque()
        self._discovery_total = [0] * len(self.probes)
        self._discovered: list[tuple[int, Answer]] = []
        self._not_sent: list[tuple[int, Request, str]] = []
        self._classified = Classified()
        self._asking = False
        self._dirty = False
        self._next_send_s = start_s

    # ----------------------------------------------------------------- the edge's calls

    def on_frame(self, frame: Frame, now_s: float) -> None:
        """Take a frame received at ``now_s``: an answer, or traffic."""
        key = (frame.arbitration_id, frame.is_extended_id)
        for out in self._by_answer.get(key, ()):
            if out.request.answered_by(frame):
                if not out.done and now_s - out.sent_s <= self.timing.answer_s:
                    self._answered(out, frame)
                return  # an answer (late ones too) is not traffic
        tally = self._tally.get(key)
        last = None if frame.is_remote_frame else frame
        if tally is None:
            self._tally[key] = _Tally(1, last, now_s, now_s)
            self._dirty |= self._asking
        else:
            tally.count += 1
            tally.last_s = now_s
            if last is not None:
                tally.last = last

    def poll(self, now_s: float) -> list[Frame]:
        """The frame to send now, if any (at most one per :attr:`ScanTiming.spacing_s`)."""
        self._expire(now_s)
        if not self._asking and now_s - self.start_s >= self.timing.listen_s:
            self._asking = self._dirty = True
            for i, probe in enumerate(self.probes):
                requests = probe.discovery()
                self._discovery_total[i] = len(requests)
                self._discovery.extend((i, r) for r in requests)
        if self._dirty:
            self._dirty = False
            self._plan(now_s)
        if not self._asking or now_s < self._next_send_s - 1e-9 or self.finished(now_s):
            return []
        frame = self._next_request(now_s)
        if frame is None:
            return []
        self._next_send_s = now_s + self.timing.spacing_s
        self.requests_sent += 1
        return [frame]

    def finished(self, now_s: float) -> bool:
        """Whether the scan's time is up."""
        return now_s - self.start_s >= self.timing.timeout_s

    # ----------------------------------------------------------------- internals

    def heard(self, now_s: float) -> list[Heard]:
        """The traffic heard so far, per identifier, with its rate: frames per second from
        the first to the latest (a controller powered during the scan is not averaged over
        the time before), a single frame's over the scan so far."""
        elapsed = max(now_s - self.start_s, 1e-9)
        return [Heard(arb, ext, t.count, (t.count - 1) / (t.last_s - t.first_s)
                      if t.last_s > t.first_s else t.count / elapsed, t.last)
                for (arb, ext), t in self._tally.items()]

    def _classify(self, now_s: float) -> Classified:
        answered = []
        for i, answer in self._discovered:
            found = self.probes[i].found_by(answer)
            if found is not None:
                answered.append((self.probes[i], found))
        return classify(self.probes, self.heard(now_s), self.own_ids, answered, self.claimed)

    def _plan(self, now_s: float) -> None:
        """Classify what was heard; start an interview for every controller new to it."""
        self._classified = self._classify(now_s)
        for s in self._classified.devices:
            key = (self.probes.index(s.probe), s.found.node_id, s.found.extended)
            if key not in self._interviews:
                self._interviews[key] = _Interview(
                    collections.deque(s.probe.requests(s.found, s.heard)))
                self._order.append(key)

    def _answered(self, out: _Out, frame: Frame | None) -> None:
        out.done = True
        answer = Answer(out.request, frame)
        if out.interview is None:
            self._discovered.append((out.probe, answer))
            self._dirty |= frame is not None
        else:
            interview = self._interviews[out.interview]
            interview.answers.append(answer)
            interview.waiting = False

    def _expire(self, now_s: float) -> None:
        outstanding = self._outstanding
        while outstanding and (outstanding[0].done
                               or now_s - outstanding[0].sent_s >= self.timing.answer_s):
            out = outstanding.popleft()
            if not out.done:
                self._answered(out, None)

    def _conflict(self, probe: int, frame: Frame) -> str | None:
        """Why ``frame`` must not go out (another protocol's identifier), or ``None``."""
        key = (frame.arbitration_id, frame.is_extended_id)
        where = hex_id(*key)
        name = self.own_ids.get(key)
        if name is not None:
            return f"{where} is wheelgate's {name}"
        mine = self.probes[probe]
        for c in self.claimed:
            if c.motor.driver != mine.DRIVER and c.owns(*key):
                m = c.motor
                return f"{where} is {m.wheel!r}'s ({m.driver} node {m.node_id}, configured)"
        others = [s for s in self._classified.devices if s.probe is not mine]
        for s in others:
            if s.probe.owns(s.found, *key):
                return f"{where} is {s.probe.TITLE} node {s.found.node_id}'s"
        for s in others:
            if s.probe.reserved(*key):
                return f"every {s.probe.TITLE} device takes {where}"
        return None

    def _send(self, probe: int, request: Request, now_s: float,
              interview: tuple[int, int, bool] | None) -> Frame:
        out = _Out(probe, request, now_s, interview)
        self._outstanding.append(out)
        self._by_answer.setdefault((request.answer_id, request.answer_extended), []).append(out)
        return request.frame

    def _next_request(self, now_s: float) -> Frame | None:
        """The next request that may go out: the interviews in turn, then discovery."""
        n = len(self._order)
        for k in range(n):
            key = self._order[(self._turn + k) % n]
            interview = self._interviews[key]
            while not interview.waiting and interview.queue:
                request = interview.queue.popleft()
                why = self._conflict(key[0], request.frame)
                if why is not None:
                    interview.notes.append(f"{request.key} not asked: {why}")
                    continue
                self._turn = (self._turn + k + 1) % n
                interview.waiting = True
                return self._send(key[0], request, now_s, key)
        while self._discovery:
            i, request = self._discovery.popleft()
            why = self._conflict(i, request.frame)
            if why is None:
                return self._send(i, request, now_s, None)
            self._not_sent.append((i, request, why))
        return None

    # ----------------------------------------------------------------- the report

    def report(self, now_s: float, bus: str) -> ScanReport:
        """What the scan found by ``now_s`` (requests still waiting count as unanswered).

        :param bus: ``interface:channel``, for the summary.
        """
        for out in self._outstanding:
            if not out.done:
                self._answered(out, None)
        self._outstanding.clear()
        final = self._classify(now_s)
        rows = sorted([*(self._row(s) for s in final.devices),
                       *(_configured_row(c) for c in final.configured)],
                      key=lambda r: (r.protocol, r.node_id or 0, r.extended))
        rows += [ScannedDevice(WHEELGATE, WHEELGATE, None, None, h.is_extended_id, None, (h,),
                               message=name) for name, h in final.own]
        rows += [ScannedDevice(UNKNOWN, UNKNOWN, None, None, h.is_extended_id, None, (h,))
                 for h in final.unknown]
        missing = self.known.missing((r.driver, r.node_id, r.extended) for r in rows)
        notes = self._scan_notes()
        if missing:
            notes.append(f"configured but not found: {', '.join(said for _, said in missing)}")
            if any(m.driver == "cia402" for m, _ in missing):
                notes.append("a CANopen node that booted before the scan and sends no "
                             "heartbeat (0x1017 = 0, its factory setting) stays silent: power "
                             "it up, or reset it (NMT), while the scan listens")
        return ScanReport(bus, now_s - self.start_s, tuple(rows), self.requests_sent,
                          tuple(notes))

    def _row(self, s: Sighting) -> ScannedDevice:
        i = self.probes.index(s.probe)
        key = (i, s.found.node_id, s.found.extended)
        interview = self._interviews.get(key)
        answers = list(interview.answers) if interview is not None else []
        answers += [a for j, a in self._discovered
                    if j == i and a.request.node_id == s.found.node_id]
        desc = s.probe.describe(s.found, s.heard, answers)
        notes = list(desc.notes)
        differs = self.known.differs(s.probe.DRIVER, s.found.node_id, s.found.extended)
        if differs is not None:
            notes.insert(0, differs)
        if interview is not None:
            notes += interview.notes
            if interview.queue:
                left = ", ".join(r.key for r in interview.queue)
                notes.append(f"{left} not asked before the scan ended: give a longer --timeout")
        elif s.probe.requests(s.found, s.heard):
            notes.append("found too late to be asked anything: give a longer --timeout")
        return ScannedDevice(s.probe.PROTOCOL, s.probe.TITLE, s.probe.DRIVER, s.found.node_id,
                             s.found.extended, s.found.seen_by, s.heard,
                             dataclasses.replace(desc, notes=tuple(notes)),
                             self.known.wheel(s.probe.DRIVER, s.found.node_id,
                                              s.found.extended))

    def _scan_notes(self) -> list[str]:
        notes = []
        if not self._asking:
            notes.append("the scan ended while listening: nothing was asked")
        left = collections.Counter(i for i, _ in self._discovery)
        for i, n in sorted(left.items()):
            p = self.probes[i]
            notes.append(f"{p.TITLE}: {n} of {self._discovery_total[i]} discovery requests "
                         f"not sent before the scan ended: give a longer --timeout")
        skipped: dict[tuple[int, str], list[tuple[int, str]]] = {}
        for i, request, why in self._not_sent:
            skipped.setdefault((i, request.key), []).append((request.node_id, why))
        for (i, key), nodes in skipped.items():
            first = nodes[0][1]
            more = f" (and {len(nodes) - 1} more)" if len(nodes) > 1 else ""
            notes.append(f"{self.probes[i].TITLE} {key} not sent to {len(nodes)} node(s): "
                         f"{first}{more}")
        return notes


def _configured_row(c: Configured) -> ScannedDevice:
    """A configured motor heard only on the identifiers its driver declares."""
    m = c.claimed.motor
    note = (f"heard on the identifiers the configuration's {m.driver} driver declares as "
            f"those of the motor of {m.wheel!r}; nothing asked")
    return ScannedDevice(m.driver, DRIVER_TITLES.get(m.driver, m.driver), m.driver, m.node_id,
                         c.heard[0].is_extended_id, CONFIGURED, c.heard,
                         Description(notes=(note,)), m.wheel)
