"""Errors on CAN (``WG_Error``) under a flood of refused requests: a request never sends on the
bus itself; its error goes out with the next cycle's reports, untracked, at most one a cycle
(the newest, but never a request's answer in place of an error of the robot's state), the
others counted in ``errors_not_sent``; and refused or projected twists log
one line per 5 s, not one each.

On simulated time with the device simulators (the TurtleBot3 at 100 Hz, as the safety tests);
what the bus got is read on the pilot's bus, what the clients got on the socket.
"""

from __future__ import annotations

import logging

import pytest

from gateway.bus.can_bus import drain
from gateway.core.types import ErrorCode, GatewayState, Twist
from gateway.wire.socket.status import status_to_json
from tests.e2e_helpers import Rig, SocketPilot, errors_on_can
from tests.runtime import safety_helpers

# The shared fixtures (safety_helpers.py), bound here so that pytest finds them.
rig = safety_helpers.rig
pilot = safety_helpers.pilot

#: Refused twists pipelined between two cycles.
FLOOD = 50


def serve_without_a_cycle(rig: Rig, pilot: SocketPilot, count: int) -> list[dict[str, object]]:
    """Serve the socket until ``count`` replies came back, running no cycle; the replies."""
    daemon = rig.daemon
    assert daemon is not None
    replies: list[dict[str, object]] = []
    for _ in range(200):
        for client, request in daemon.server.poll(0.01):
            daemon.handle(client, request, rig.t)
        replies += pilot.messages()
        if len(replies) >= count:
            break
    assert len(replies) == count, replies[-3:]
    return replies


def disable(rig: Rig, pilot: SocketPilot) -> None:
    pilot.send(op="disable")
    rig.advance(0.05)
    assert rig.gw.state is GatewayState.DISABLED
    pilot.messages()
    drain(rig.pilot)


def test_refused_twists_between_cycles_put_one_error_on_can_the_next_cycle(
    rig: Rig, pilot: SocketPilot
) -> None:
    """Before, each refused twist sent its WG_Error at once from the request handler: 10,000
    frames/s on the bus for a client that pipelines them."""
    disable(rig, pilot)
    gw = rig.gw
    sent0, reported0 = gw.edge.counts.frames_sent, gw.counts.errors_reported
    pilot.sock.sendall(b"".join(b'{"op":"twist","vx":0.1,"id":%d}\n' % i for i in range(FLOOD)))
    replies = serve_without_a_cycle(rig, pilot, FLOOD)
    # Every client still gets its own error reply, unchanged.
    assert [r["id"] for r in replies] == list(range(FLOOD))
    for reply in replies:
        assert reply["ok"] is False
        error = reply["error"]
        assert isinstance(error, dict) and error["code"] == "not_enabled", reply
    # Nothing reached the bus between the cycles.
    assert gw.edge.counts.frames_sent == sent0
    assert list(drain(rig.pilot)) == []
    sends: list[tuple[list[int], bool]] = []
    send = gw.edge.send

    def record(frames: list, now_s: float | None = None, tracked: bool = True) -> bool:  # type: ignore[type-arg]
        sends.append(([f.arbitration_id for f in frames], tracked))
        return send(frames, now_s, tracked)

    gw.edge.send = record  # type: ignore[method-assign]
    rig.advance(rig.period)
    reports = errors_on_can(rig)
    assert len(reports) == 1
    assert reports[0].code is ErrorCode.NOT_ENABLED
    assert reports[0].count == gw.publisher._error_count  # every error counted
    # ... sent untracked, with the reports, not in the burst of commands.
    error_id = gw.wg.ids.error
    assert [tracked for ids, tracked in sends if error_id in ids] == [False]
    assert gw.counts.errors_reported - reported0 == FLOOD
    assert gw.counts.errors_not_sent == FLOOD - 1
    daemon = rig.daemon
    assert daemon is not None
    counters = status_to_json(daemon.status())["counters"]
    assert isinstance(counters, dict) and counters["errors_not_sent"] == FLOOD - 1
    rig.advance(0.1)  # nothing new: no more
    assert errors_on_can(rig) == []


def test_an_error_of_the_cycle_displaces_the_refused_requests_before_it(
    rig: Rig, pilot: SocketPilot
) -> None:
    """A CAN sender gets the WG_Error of its own refused twist (with its counter), whatever a
    socket client's refused twists did before in that cycle."""
    disable(rig, pilot)
    pilot.sock.sendall(b'{"op":"twist","vx":0.1}\n' * 5)
    serve_without_a_cycle(rig, pilot, 5)
    counter = rig.counter & 0xFF
    rig.send_can_twist(Twist(0.1, 0.0, 0.0))
    rig.advance(rig.period)
    reports = errors_on_can(rig)
    assert [(r.code, r.twist_counter) for r in reports] == [(ErrorCode.NOT_ENABLED, counter)]
    assert rig.gw.counts.errors_not_sent == 5


@pytest.mark.parametrize("state_first", [True, False], ids=["state-first", "state-last"])
def test_refused_requests_never_displace_an_error_of_the_robots_state(
    rig: Rig, pilot: SocketPilot, state_first: bool
) -> None:
    """A lost commander's error (the bridge's deadman, reported between cycles) reaches CAN
    whether refused twists were served before or after it: an answer to a request never takes
    the place of a pending error of the robot's own state (a review saw the deadman's error
    displaced by a planner's refused twist)."""
    disable(rig, pilot)

    def lost() -> None:
        rig.gw.report_error(ErrorCode.COMMAND_TIMEOUT, "commander teleop1 disappeared")

    if state_first:
        lost()
    pilot.sock.sendall(b'{"op":"twist","vx":0.1}\n' * 5)
    serve_without_a_cycle(rig, pilot, 5)
    if not state_first:
        lost()
    rig.advance(rig.period)
    assert [r.code for r in errors_on_can(rig)] == [ErrorCode.COMMAND_TIMEOUT]
    assert rig.gw.counts.errors_not_sent == 5


def test_refused_twists_log_a_line_per_5_s_with_the_count(
    rig: Rig, pilot: SocketPilot, caplog: pytest.LogCaptureFixture
) -> None:
    """Before, every refused twist logged a line (INFO) and every projected one a WARNING:
    13,000 to 63,000 lines in 2 s under a pipelining client, hundreds of missed cycles."""
    caplog.set_level(logging.INFO, logger="gateway.runtime.loop")
    disable(rig, pilot)
    pilot.sock.sendall(b'{"op":"twist","vx":0.1}\n' * FLOOD)
    serve_without_a_cycle(rig, pilot, FLOOD)
    refused = [r for r in caplog.records if "socket twist refused" in r.getMessage()]
    assert len(refused) == 1, [r.getMessage() for r in refused[:3]]
    rig.advance(5.1)
    pilot.sock.sendall(b'{"op":"twist","vx":0.1}\n' * 2)
    serve_without_a_cycle(rig, pilot, 2)
    lines = [r.getMessage() for r in caplog.records if "socket twist refused" in r.getMessage()]
    assert len(lines) == 2
    assert lines[1].endswith(f"({FLOOD} such twists since the last such line)")


@pytest.mark.parametrize("rig", [{"infeasible_policy": "project"}], indirect=True)
def test_projected_twists_log_a_warning_per_5_s_with_the_count(
    rig: Rig, pilot: SocketPilot, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="gateway.runtime.loop")
    pilot.sock.sendall(b'{"op":"twist","vx":0.1,"vy":0.05}\n' * FLOOD)
    replies = serve_without_a_cycle(rig, pilot, FLOOD)
    assert all(r["ok"] is True and r["projected"] is True for r in replies)

    def twist_and_read(_: Rig) -> None:
        pilot.send(op="twist", vx=0.1, vy=0.05)
        pilot.messages()  # the replies read: the server keeps reading the requests

    rig.advance(5.1, twist_and_read)
    projected = [r for r in caplog.records if "socket twist projected" in r.getMessage()]
    assert [r.levelno for r in projected] == [logging.WARNING] * 2
    assert projected[1].getMessage().endswith("such twists since the last such line)")
