"""Reading keys without cutting an escape sequence in two (:mod:`gateway.apps.keyboard`):
a Page Down or an arrow split by a short read is one key, not an Esc that quits."""

from __future__ import annotations

import contextlib
import os
import threading
import time

import pytest

from gateway.apps.jog.keys import split_keys
from gateway.apps.keyboard import ESC_WAIT_S, read_keys, unfinished_escape


@pytest.mark.parametrize(("data", "unfinished"), [
    (b"", False), (b"abc", False), (b"\x1b", True), (b"a\x1b", True), (b"\x1b[", True),
    (b"\x1b[6", True), (b"\x1b[1;5", True), (b"\x1b[6~", False), (b"\x1b[A", False),
    (b"\x1bO", True), (b"\x1bOP", False), (b"\x1bx", False), (b"\x1b[6~ ", False),
])
def test_unfinished_escape(data: bytes, unfinished: bool) -> None:
    assert unfinished_escape(data) is unfinished


def test_a_sequence_cut_by_the_read_size_is_read_whole() -> None:
    r, w = os.pipe()
    try:
        sent = b" " * 63 + b"\x1b[6~" + b"n"
        os.write(w, sent)
        data = read_keys(r, 64)
        assert data == sent  # the first read ended in ESC alone: the rest was taken too
        assert split_keys(data)[-2:] == ["\x1b[6~", "n"] and "\x1b" not in split_keys(data)
    finally:
        os.close(r)
        os.close(w)


def test_the_rest_of_a_sequence_that_comes_late_is_waited_for_and_a_lone_esc_is_esc() -> None:
    r, w = os.pipe()
    try:
        os.write(w, b"\x1b[")
        later = threading.Timer(0.01, os.write, (w, b"5~"))
        later.start()
        assert read_keys(r, 64, wait_s=10.0) == b"\x1b[5~"  # (a long wait: a loaded machine)
        later.join()
        os.write(w, b"\x1b")
        started = time.monotonic()
        assert split_keys(read_keys(r, 64)) == ["\x1b"]  # Esc, after the wait
        assert time.monotonic() - started >= ESC_WAIT_S * 0.9
        os.close(w)
        w = -1
        assert read_keys(r, 64) == b""  # end of input
    finally:
        os.close(r)
        if w >= 0:
            os.close(w)


def test_a_stream_of_escape_bytes_holds_the_reader_one_wait_at_most() -> None:
    """A held Alt+[ (ESC [ again and again) or a paste of ESC bytes: one deadline for the
    whole read, so the loop that called it (jog's deadman, monitor's screen) goes on."""
    r, w = os.pipe()
    stop = threading.Event()

    def feed() -> None:
        while not stop.is_set():
            with contextlib.suppress(BlockingIOError):  # (a full pipe: the reader is done)
                os.write(w, b"\x1b[")
            time.sleep(0.002)

    os.set_blocking(w, False)
    feeder = threading.Thread(target=feed, daemon=True)
    try:
        feeder.start()
        time.sleep(0.01)
        started = time.monotonic()
        data = read_keys(r, 64, wait_s=0.2)
        took = time.monotonic() - started
        assert data.startswith(b"\x1b[") and unfinished_escape(data)
        assert took < 2.0, took  # bounded by the one deadline (0.2 s), not by the stream
    finally:
        stop.set()
        feeder.join()
        os.close(r)
        os.close(w)
