"""Real-time set-up of the loop thread: :func:`realtime_setup`.

``gc.freeze()``, ``SCHED_FIFO``, CPU pinning and ``mlockall``, each as far as the process is
allowed; a refusal by the system is a warning and a note, never an error.
"""

from __future__ import annotations

import ctypes
import errno
import gc
import logging
import os
import platform
import resource

from gateway.core.errors import ConfigError

log = logging.getLogger(__name__)

#: mlockall flags (MCL_CURRENT, MCL_FUTURE) by machine prefix; Linux uses 1 and 2 elsewhere.
_MCL_FLAGS = {"ppc": (0x2000, 0x4000), "sparc": (0x2000, 0x4000), "alpha": (0x2000, 0x4000)}


def _mcl_flags() -> int:
    machine = platform.machine().lower()
    for prefix, (current, future) in _MCL_FLAGS.items():
        if machine.startswith(prefix):
            return current | future
    return 1 | 2


def _libc() -> ctypes.CDLL:
    """The C library of this process (patched in tests)."""
    return ctypes.CDLL(None, use_errno=True)


def _refused(notes: list[str], text: str) -> None:
    log.warning("%s", text)
    notes.append(text)


def _set_fifo(priority: int, notes: list[str]) -> None:
    low, high = os.sched_get_priority_min(os.SCHED_FIFO), os.sched_get_priority_max(os.SCHED_FIFO)
    if not low <= priority <= high:
        raise ConfigError(f"real-time priority: expected {low}..{high}, got {priority}")
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as err:
        limit = resource.getrlimit(resource.RLIMIT_RTPRIO)[0]
        _refused(notes, f"SCHED_FIFO {priority} refused ({err.strerror or err}; RLIMIT_RTPRIO "
                        f"is {limit}; set LimitRTPRIO= in the unit): staying on SCHED_OTHER")
    else:
        notes.append(f"SCHED_FIFO priority {priority} for the loop thread")


def _pin(cpu: int, notes: list[str]) -> None:
    try:
        os.sched_setaffinity(0, {cpu})
    except OSError as err:
        allowed = sorted(os.sched_getaffinity(0))
        _refused(notes, f"pinning to CPU {cpu} refused ({err.strerror or err}; "
                        f"allowed CPUs {allowed}): not pinned")
    else:
        notes.append(f"loop thread pinned to CPU {cpu}")


def _lock_memory(notes: list[str]) -> None:
    try:
        libc = _libc()
        result = libc.mlockall(_mcl_flags())
    except (OSError, AttributeError) as err:
        _refused(notes, f"mlockall unavailable ({err}): memory not locked")
        return
    if result != 0:
        code = ctypes.get_errno()
        reason = os.strerror(code) if code else "unknown error"
        hint = "; set LimitMEMLOCK= in the unit" if code in (errno.EPERM, errno.ENOMEM) else ""
        _refused(notes, f"mlockall refused ({reason}{hint}): memory not locked")
    else:
        notes.append("memory locked (mlockall MCL_CURRENT|MCL_FUTURE)")


def realtime_setup(priority: int | None, cpu: int | None, lock_memory: bool) -> list[str]:
    """Prepare the calling thread and the process for the control loop.

    Call it from the loop thread, after imports, configuration and bus set-up, and after any
    helper thread has been started (threads created later inherit ``SCHED_FIFO``):

    1. ``gc.collect()`` then ``gc.freeze()``: start-up objects leave the collector's view, so
       later collections are short.  Always done.
    2. ``SCHED_FIFO`` at ``priority`` for the calling thread (Linux applies ``pid 0`` to the
       thread).  An unprivileged user needs ``LimitRTPRIO=`` in the unit.
    3. CPU affinity of the calling thread to ``cpu``.
    4. ``mlockall(MCL_CURRENT | MCL_FUTURE)``.  Needs ``LimitMEMLOCK=`` and, to keep the
       locked size sane, ``MALLOC_ARENA_MAX=1`` and small thread stacks.

    Missing privileges or unsupported calls never raise: each refusal is logged as a warning
    and reported in the notes, and the loop runs with normal scheduling.

    :param priority: ``SCHED_FIFO`` priority 1..99; ``None`` or 0 leaves the policy alone.
    :param cpu: CPU number to pin to; ``None`` or negative leaves the affinity alone.
    :param lock_memory: lock all current and future memory of the process.
    :return: human-readable notes of what was applied and what was refused.
    :raises ConfigError: if ``priority`` is outside the range of ``SCHED_FIFO``.
    """
    notes: list[str] = []
    gc.collect()
    gc.freeze()
    notes.append(f"gc: {gc.get_freeze_count()} start-up objects frozen")
    if priority:
        if hasattr(os, "sched_setscheduler"):
            _set_fifo(priority, notes)
        else:
            _refused(notes, "SCHED_FIFO is not supported on this platform")
    if cpu is not None and cpu >= 0:
        if hasattr(os, "sched_setaffinity"):
            _pin(cpu, notes)
        else:
            _refused(notes, "CPU pinning is not supported on this platform")
    if lock_memory:
        _lock_memory(notes)
    return notes
