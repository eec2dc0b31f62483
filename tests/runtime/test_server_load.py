"""The control socket under load: subscriptions, slow and silent clients, a thousand clients at
once, running out of file descriptors, and the poll budgets."""

from __future__ import annotations

import contextlib
import json
import os
import resource
import socket
import threading
import time
from typing import TYPE_CHECKING

import pytest

from gateway.core.types import GatewayState
from gateway.runtime.client import ClientTimeoutError, ControlClient
from gateway.runtime.server import ControlServer, ServerCounters
from gateway.wire.socket import (
    CommandRequest,
    Op,
    ProtocolError,
    Topic,
    event,
    reply_ok,
)
from tests.runtime import server_helpers
from tests.runtime.server_helpers import (
    WAIT_S,
    Events,
    LoopThread,
    RawClient,
    lines,
    open_fds,
    poll_until,
    raw_client,
    respond,
)

if TYPE_CHECKING:
    from pathlib import Path

pytestmark = server_helpers.MARKS


# The shared fixtures (server_helpers.py), bound here so that pytest finds them.
sock_dir = server_helpers.sock_dir
sock_path = server_helpers.sock_path
server = server_helpers.server


# -- output, subscriptions and slow readers --------------------------------------------------


def test_publish_reaches_only_subscribers(server: ControlServer, sock_path: Path) -> None:
    with (
        LoopThread(server) as loop,
        ControlClient(sock_path) as odometry,
        ControlClient(sock_path) as status,
        ControlClient(sock_path) as idle,
    ):
        assert odometry.request({"op": "subscribe", "topics": ["odometry"]})["topics"] == [
            "odometry"
        ]
        assert status.request({"op": "subscribe", "topics": ["status", "odometry"]})["ok"]
        assert idle.request({"op": "status"})["ok"]
        loop.outbox.put((Topic.ODOMETRY, event(Topic.ODOMETRY, {"x": 1.0})))
        loop.outbox.put((Topic.STATUS, event(Topic.STATUS, {"state": GatewayState.RUNNING})))
        assert next(odometry.events(WAIT_S)) == {"event": "odometry", "x": 1.0}
        stream = status.events(WAIT_S)
        assert next(stream) == {"event": "odometry", "x": 1.0}
        assert next(stream) == {"event": "status", "state": "running"}
        # Both events were published before this reply was sent; none reached `idle`.
        assert idle.request({"op": "status"})["ok"]
        with pytest.raises(ClientTimeoutError):
            next(idle.events(0.01))
        # After unsubscribing, `status` gets the next event but `odometry` does not.
        assert odometry.request({"op": "unsubscribe"})["ok"]
        loop.outbox.put((Topic.ODOMETRY, event(Topic.ODOMETRY, {"x": 2.0})))
        assert next(stream) == {"event": "odometry", "x": 2.0}
        assert odometry.request({"op": "status"})["ok"]
        with pytest.raises(ClientTimeoutError):
            next(odometry.events(0.01))


def test_slow_subscriber_is_disconnected(sock_path: Path) -> None:
    with (
        ControlServer(sock_path, max_pending_bytes_per_client=65536) as srv,
        raw_client(sock_path) as raw,
    ):
        raw.send(b'{"op":"subscribe","topics":["status"],"id":1}\n')
        ((cid, item),) = poll_until(srv, bool, "the subscription")
        srv.reply(cid, respond(srv, cid, item))
        assert srv.has_subscribers(Topic.STATUS)
        data = event(Topic.STATUS, {"pad": "x" * 1000})
        published = 0
        while srv.publish(Topic.STATUS, data):  # the client never reads
            published += 1
            assert published < 10_000, "the slow subscriber was never disconnected"
        counters = srv.counters
        assert (counters.slow_disconnects, counters.clients) == (1, 0)
        assert not srv.has_subscribers(Topic.STATUS)
        assert srv.reply(cid, b"late\n") is False
        # What the kernel took is still readable, then the stream ends.
        assert raw.line() == {"ok": True, "id": 1, "topics": ["status"]}
        received = 0
        while chunk := raw.sock.recv(1 << 16):
            received += len(chunk)
        assert 0 < received <= published * len(data)


def test_unknown_client_ids_are_ignored(server: ControlServer) -> None:
    assert server.reply(999, b"x\n") is False
    assert server.subscribe(999, {Topic.STATUS}) is False
    assert server.unsubscribe(999) is False
    assert server.publish(Topic.STATUS, b"x\n") == 0
    assert server.counters == ServerCounters()


def test_a_thousand_clients_at_once_displace_the_oldest_silent_ones(sock_path: Path) -> None:
    """Each connection beyond max_clients closes the oldest that has sent nothing yet: the
    last 600 are served, the first 400 were displaced (counted as refused)."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    need = 3000
    if soft < need:
        if hard != resource.RLIM_INFINITY and hard < need:
            pytest.skip(f"needs {need} file descriptors, the hard limit is {hard}")
        resource.setrlimit(resource.RLIMIT_NOFILE, (need, hard))
    try:
        before = open_fds()
        served, counters = _thousand_clients(sock_path, total=1000, max_clients=600)
        assert open_fds() == before
    finally:
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
    assert served == list(range(400, 1000))
    assert (counters.accepted, counters.refused, counters.evicted) == (1000, 400, 0)


def _thousand_clients(path: Path, total: int, max_clients: int) -> tuple[list[int], ServerCounters]:
    """Connect ``total`` clients one after the other, then send a status request on each:
    the indices of those answered."""
    served: list[int] = []
    clients: list[socket.socket] = []
    with ControlServer(path, max_clients=max_clients) as srv:
        try:
            with LoopThread(srv):
                for _ in range(total):
                    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                    clients.append(sock)
                    sock.settimeout(WAIT_S)
                    sock.connect(str(path))
                deadline = time.monotonic() + WAIT_S
                while srv.counters.accepted < total:  # all accepted before anyone sends
                    assert time.monotonic() < deadline, f"accepted only {srv.counters}"
                    time.sleep(0.01)
                for index, sock in enumerate(clients):
                    with contextlib.suppress(BrokenPipeError, ConnectionResetError):
                        sock.sendall(b'{"op":"status","id":%d}\n' % index)
                for index, sock in enumerate(clients):
                    data = b""
                    with contextlib.suppress(ConnectionResetError):
                        while not data.endswith(b"\n") and (chunk := sock.recv(4096)):
                            data += chunk
                    if data:
                        assert json.loads(data) == {"ok": True, "id": index, "op": "status"}
                        served.append(index)
        finally:
            for sock in clients:
                sock.close()
        counters = srv.counters
    return served, counters


def test_out_of_file_descriptors_each_new_connection_closes_the_one_idle_longest(
    server: ControlServer, sock_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """No descriptor free and three connections waiting: the first takes the spare
    descriptor's place, each next one closes the client idle longest (none of them sent a
    line), as at max_clients; no exception, one log line."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    clients = [socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) for _ in range(3)]
    try:
        for sock in clients:
            sock.connect(str(sock_path))  # waits in the backlog
        lowest_free = os.open(os.devnull, os.O_RDONLY)
        os.close(lowest_free)
        resource.setrlimit(resource.RLIMIT_NOFILE, (lowest_free, hard))  # no fd is free
        try:
            assert server.poll(0.02) == []  # accept fails with EMFILE: no exception
        finally:
            resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
        assert caplog.text.count("accept failed") == 1
        counters = server.counters
        assert (counters.accepted, counters.refused, counters.clients) == (3, 2, 1)
    finally:
        for sock in clients:
            sock.close()


# -- budgets, timeouts and eviction ----------------------------------------------------------


def ids(events: Events) -> list[object]:
    """The request ids of ``events`` (a parse error's when it could be read)."""
    return [item.request_id if isinstance(item, ProtocolError) else item.id for _, item in events]


def test_a_poll_takes_at_most_its_budget_round_robin(
    server: ControlServer, sock_path: Path
) -> None:
    with raw_client(sock_path) as flood, raw_client(sock_path) as other:
        flood.send(lines("stop", 200))
        other.send(b'{"op":"estop","id":"e"}\n')
        batches: list[Events] = []
        while sum(map(len, batches)) < 201:
            assert len(batches) < 50, f"only {sum(map(len, batches))} requests in 50 polls"
            batches.append(server.poll(0.05))
        first = next(batch for batch in batches if batch)
    assert max(map(len, batches)) == ControlServer.ROUND_REQUESTS
    # One line per client per turn: the other client's estop is not behind the flood.
    assert CommandRequest(Op.ESTOP, "e") in [item for _, item in first[:2]]
    flood_ids = [rid for batch in batches for rid in ids(batch) if rid != "e"]
    assert flood_ids == list(range(200))
    assert server.counters.deferred >= 3


def test_a_cycle_budget_spans_its_polls_and_the_rest_waits_unread(
    server: ControlServer, sock_path: Path
) -> None:
    with raw_client(sock_path) as raw:
        raw.send(lines("stop", 100))
        server.begin_cycle(0.005)  # 12,800 requests/s: 64 in this cycle, whatever the polls
        taken = poll_until(server, bool, "the first requests")
        for _ in range(3):
            taken += server.poll(0.0)
        assert len(taken) == 64
        cpu = time.thread_time()
        assert server.poll(0.1) == []  # the rest waits unread: a real wait, no spin
        assert time.thread_time() - cpu < 0.05
        server.begin_cycle(0.005)
        taken += poll_until(server, lambda ev: len(ev) >= 36, "the rest")
    assert ids(taken) == list(range(100))


def test_costly_ops_wait_for_their_allowance_without_holding_up_others(
    server: ControlServer, sock_path: Path
) -> None:
    with raw_client(sock_path) as monitor, raw_client(sock_path) as pilot:
        monitor.send(lines("status", 3) + b'{"op":"stop","id":3}\n')
        pilot.send(b'{"op":"twist","vx":0.1,"id":"t"}\n{"op":"estop","id":"e"}\n')
        cycles = []
        for _ in range(4):
            server.begin_cycle(0.005)  # status and estop: 200/s each, one per cycle
            taken: Events = []
            for _ in range(3):
                taken += server.poll(0.02)
            cycles.append(set(ids(taken)))
    # The monitor's statuses come one per cycle, its stop behind them; the pilot's twist and
    # estop are not held up by them.
    assert cycles == [{0, "t", "e"}, {1}, {2, 3}, set()]


def test_a_full_server_closes_the_longest_idle_client_for_a_new_one(sock_path: Path) -> None:
    def connected(count: int) -> None:
        poll_until(srv, lambda ev: srv.counters.accepted == count, f"connection {count}")

    def answered(raw: RawClient, rid: int) -> None:
        raw.send(b'{"op":"stop","id":%d}\n' % rid)
        assert ids(poll_until(srv, bool, f"request {rid}")) == [rid]

    with (
        ControlServer(sock_path, max_clients=3) as srv,
        raw_client(sock_path) as silent,
        raw_client(sock_path) as older,
        raw_client(sock_path) as newer,
    ):
        connected(3)
        answered(older, 2)
        answered(newer, 3)
        with raw_client(sock_path) as fourth:
            connected(4)  # closes the one that never sent a line
            assert silent.at_eof()
            assert (srv.counters.refused, srv.counters.evicted) == (1, 0)
            answered(fourth, 4)
            with raw_client(sock_path) as fifth:
                connected(5)  # nobody silent: closes the one idle longest
                assert older.at_eof()
                assert (srv.counters.refused, srv.counters.evicted) == (1, 1)
                answered(fifth, 5)
                answered(newer, 6)
                assert srv.counters.clients == 3


def test_idle_and_half_line_clients_are_closed_subscribers_and_talkers_kept(
    sock_path: Path,
) -> None:
    with ControlServer(sock_path, idle_timeout_s=0.5, partial_timeout_s=0.5) as srv:
        with (
            raw_client(sock_path) as idle,
            raw_client(sock_path) as half,
            raw_client(sock_path) as listener,
            raw_client(sock_path) as talker,
        ):
            half.send(b'{"op":"st')
            listener.send(b'{"op":"subscribe","topics":["error"],"id":1}\n')
            end = time.monotonic() + 1.5
            while time.monotonic() < end:
                talker.send(b"\n")  # a blank line is a sign of life too
                for cid, item in srv.poll(0.05):
                    srv.reply(cid, respond(srv, cid, item))
            assert idle.at_eof()
            assert half.at_eof()
            assert listener.line()["topics"] == ["error"]
            counters = srv.counters
    assert (counters.idle_timeouts, counters.partial_timeouts, counters.clients) == (1, 1, 2)
    assert counters.dropped_partial == 0  # closed by the server, not a disconnect


def test_a_client_that_does_not_read_its_replies_is_slowed_not_dropped(sock_path: Path) -> None:
    count = 400
    with (
        ControlServer(sock_path, max_pending_bytes_per_client=16384) as srv,
        raw_client(sock_path) as raw,
    ):
        raw.send(lines("status", count))
        answered = 0
        received: list[int] = []

        def serve(seconds: float) -> None:
            """Poll and answer (and flush) until every reply has been read, or ``seconds``."""
            nonlocal answered
            end = time.monotonic() + seconds
            while time.monotonic() < end and len(received) < count:
                for cid, item in srv.poll(0.01):
                    assert isinstance(item, CommandRequest)
                    srv.reply(cid, reply_ok(item.id, {"pad": "x" * 2000}))
                    answered += 1

        serve(0.5)
        # The kernel's buffer and 8 KiB of queue filled up: its requests are no longer read.
        assert 0 < answered < count

        def drain() -> None:
            while len(received) < count:
                received.append(raw.line()["id"])

        reader = threading.Thread(target=drain, name="test-drain", daemon=True)
        reader.start()
        serve(WAIT_S)
        reader.join(WAIT_S)
        assert received == list(range(count))
        assert (srv.counters.slow_disconnects, srv.counters.clients) == (0, 1)


def test_all_subscribers_queues_together_are_capped(
    sock_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with (
        ControlServer(sock_path) as srv,
        raw_client(sock_path) as first,
        raw_client(sock_path) as second,
    ):
        srv.MAX_PENDING_BYTES_TOTAL = 48 * 1024  # less than one client's own 64 KiB
        first.send(b'{"op":"subscribe","topics":["status"]}\n')
        second.send(b'{"op":"subscribe","topics":["status"]}\n')
        for cid, item in poll_until(srv, lambda ev: len(ev) == 2, "the subscriptions"):
            srv.reply(cid, respond(srv, cid, item))
        data = event(Topic.STATUS, {"pad": "x" * 1000})
        published = 0
        while srv.counters.slow_disconnects == 0:  # neither reads
            srv.publish(Topic.STATUS, data)
            published += 1
            assert published < 5000, "no subscriber was disconnected"
        assert srv.counters.clients == 1
    assert "bytes of output pending for all clients, no room for more (at most 49152)" in (
        caplog.text
    )
