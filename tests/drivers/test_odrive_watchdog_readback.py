"""The 0.6 watchdog setup confirms only on its own read-back (:class:`WatchdogSetup`).

Replies are fed to the pure setup as the driver would: a timeout read back other than the one
written, a previous run's values, or a TxSdo that comes before the firmware version was
checked, never confirms; the setup then fails naming what it read.
"""

from __future__ import annotations

import struct

from drivers.odrive.watchdog import WatchdogEndpoints, WatchdogSetup
from gateway.core.protection import ProtectionState

ENDPOINTS = WatchdogEndpoints("0.6.10", 201, 200)
ENABLE, TIMEOUT = ENDPOINTS.enable_id, ENDPOINTS.timeout_id


def f32(value: float) -> bytes:
    return struct.pack("<f", value)


def state(setup: WatchdogSetup) -> ProtectionState:
    return setup.state  # (read through a call: each read is after a reply)


def started(now_s: float = 0.0) -> WatchdogSetup:
    setup = WatchdogSetup(ENDPOINTS, 0.25, 0x064, 0x060, False)
    setup.start(now_s)
    return setup


def test_a_timeout_read_back_other_than_written_never_confirms() -> None:
    # An axis that keeps another watchdog_timeout (clamped, or a saved value) would let the
    # wheel run on longer than configured after the host falls silent.
    setup = started()
    setup.on_version("0.6.10", "", 0.01)
    for timeout in (1.0, 0.2500001, 0.0):
        setup.on_tx_sdo(TIMEOUT, f32(timeout))
        setup.on_tx_sdo(ENABLE, b"\x01")
        assert state(setup) is ProtectionState.PENDING
    t = 0.01
    while state(setup) is ProtectionState.PENDING:
        t += WatchdogSetup.RETRY_S
        setup.poll(t)
    assert state(setup) is ProtectionState.FAILED
    assert "'watchdog_timeout': 0.0" in setup.why and "watchdog_timeout 0.25" in setup.why


def test_a_new_start_forgets_the_last_runs_read_back() -> None:
    setup = started()
    setup.on_version("0.6.10", "", 0.01)
    setup.on_tx_sdo(TIMEOUT, f32(0.25))
    setup.on_tx_sdo(ENABLE, b"\x01")
    assert state(setup) is ProtectionState.CONFIRMED
    # Disabled, then the axis rebooted with the watchdog unsaved: enable again.
    setup.start(1.0)
    setup.on_version("0.6.10", "", 1.01)
    setup.on_tx_sdo(TIMEOUT, f32(0.25))
    assert state(setup) is ProtectionState.PENDING  # enable_watchdog not read back yet
    setup.on_tx_sdo(ENABLE, b"\x00")
    assert state(setup) is ProtectionState.PENDING


def test_a_read_back_before_the_version_check_is_ignored() -> None:
    # Another host's read, or replies of a setup cut short, must not skip the version check
    # (the endpoint IDs of another firmware name other parameters).
    setup = started()
    setup.on_tx_sdo(TIMEOUT, f32(0.25))
    setup.on_tx_sdo(ENABLE, b"\x01")
    assert state(setup) is ProtectionState.PENDING
    assert setup.on_version("0.6.9", "", 0.01) == []
    assert state(setup) is ProtectionState.FAILED
    assert "firmware 0.6.9" in setup.why and "nothing was written" in setup.why
