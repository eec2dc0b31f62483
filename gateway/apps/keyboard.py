"""Reading keys from a terminal for ``jog`` and ``monitor``, without cutting a key in two.

A key that is an escape sequence (an arrow ``ESC [ A``, Page Down ``ESC [ 6 ~``, Alt+x ``ESC
x``) arrives as several bytes, which one ``read`` may split: the first read ending in ``ESC``
alone would be taken for the Esc key, which quits both programs.  :func:`read_keys` reads what
is there and, while it ends inside an escape sequence, waits a moment for the rest
(:data:`ESC_WAIT_S`, as ncurses' ``ESCDELAY`` and vim's ``ttimeout`` do): what a terminal sends
for one key comes at once, so an Esc typed alone is known as such after that moment.
:func:`gateway.apps.jog.keys.split_keys` then cuts the bytes into keys.
"""

from __future__ import annotations

import os
import select
import time

__all__ = ["ESC_WAIT_S", "read_keys", "unfinished_escape"]

#: How long the rest of an escape sequence may take to follow its ESC (s).
ESC_WAIT_S = 0.05
_ESC = 0x1B
#: The end of what was read that is searched for an unfinished sequence (bytes): longer than
#: any key's sequence.
_TAIL = 64


def unfinished_escape(data: bytes) -> bool:
    """Whether ``data`` ends inside an escape sequence: a last ESC, ``ESC [`` and parameter
    bytes without their final byte, or ``ESC O`` (the forms :func:`split_keys
    <gateway.apps.jog.keys.split_keys>` takes as one key).

    >>> unfinished_escape(b"a\\x1b"), unfinished_escape(b"\\x1b[6"), unfinished_escape(b"\\x1b[6~")
    (True, True, False)
    """
    start = data.rfind(_ESC)
    if start < 0:
        return False
    rest = data[start + 1:]
    if not rest:
        return True
    if rest[:1] == b"O":
        return len(rest) == 1
    if rest[:1] != b"[":
        return False
    return all(0x20 <= b <= 0x3F for b in rest[1:])  # no final byte yet


def read_keys(fd: int, size: int, wait_s: float = ESC_WAIT_S) -> bytes:
    """One ``os.read`` of ``fd`` (up to ``size`` bytes; ``b""`` at the end of input), and
    while it ends inside an escape sequence, what follows within ``wait_s`` of the call (one
    deadline: a stream of escape bytes, a held Alt+[ or a paste, holds the caller that long
    at most, and is then cut into keys as it came).

    :raises OSError: as ``os.read`` (EIO: the terminal is gone).
    """
    data = os.read(fd, size)
    if not data or not unfinished_escape(data):
        return data
    buf, end = bytearray(data), time.monotonic() + wait_s
    while (left := end - time.monotonic()) > 0.0 and select.select([fd], [], [], left)[0]:
        more = os.read(fd, size)
        if not more:
            break
        buf += more
        if not unfinished_escape(bytes(buf[-_TAIL:])):
            break
    return bytes(buf)
