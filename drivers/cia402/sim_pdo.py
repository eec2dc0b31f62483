"""The PDO exchange of the simulated CiA 402 drive (:class:`PdoExchange`, a part of
:class:`~drivers.cia402.sim.Cia402Simulator`): RPDOs applied at once or at the next SYNC,
TPDOs on SYNC or by event (event timer 0x18xx:05, or a change of a mapped statusword).

CiA 301: a PDO is valid while bit 31 of its COB-ID (0x14xx:01 / 0x18xx:01) is clear; with
transmission type 1..240 an RPDO acts at the next SYNC and a TPDO goes out every n-th SYNC;
with 254/255 (event-driven) an RPDO acts when it comes and a TPDO goes out on its event.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from gateway.core.types import Frame

if TYPE_CHECKING:
    from drivers.cia402.enums import NmtState
    from drivers.cia402.faults import SdoAbortCode
    from drivers.cia402.sim_od import SimObjectDictionary

#: The largest synchronous transmission type (1..240: every n-th SYNC).
_SYNC_TYPES_MAX = 240
#: From this transmission type on, a TPDO is event-driven (254 manufacturer, 255 profile).
_EVENT_TYPES_MIN = 254


class PdoExchange:
    """The PDOs of a simulated CiA 402 drive.

    The simulator that inherits it provides the attributes below and :meth:`_write`,
    :meth:`_refresh` and :meth:`_step_states`.
    """

    od: SimObjectDictionary
    nmt: NmtState
    #: Counters for assertions: SYNCs seen, RPDOs applied, bad PDOs.
    syncs: int
    rpdos: int
    pdo_errors: int
    _now: float
    _last_rpdo_s: float | None

    def _reset_pdos(self) -> None:
        """Forget the PDOs under way (power-on, reset communication)."""
        self._pending: dict[int, bytes] = {}
        self._tpdo_last_s = [0.0] * 4
        self._tpdo_last_sw: list[int | None] = [None] * 4
        self._sync_counter = [0] * 4

    def _write(self, index: int, sub: int, data: bytes, *, sdo: bool) -> SdoAbortCode | None:
        raise NotImplementedError  # the simulator's

    def _refresh(self) -> None:
        raise NotImplementedError  # the simulator's

    def _step_states(self) -> None:
        raise NotImplementedError  # the simulator's

    def _on_rpdo(self, k: int, data: bytes) -> None:
        mapped = self.od.mapped(0x1600 + k)
        if len(data) < sum(bits for _, _, bits in mapped) // 8:
            self.pdo_errors += 1
            return
        if self.od.get(0x1400 + k, 2) <= _SYNC_TYPES_MAX:
            self._pending[k] = data  # synchronous: acts at the next SYNC
        else:
            self._apply_rpdo(k, data)

    def _apply_rpdo(self, k: int, data: bytes) -> None:
        self.rpdos += 1
        self._last_rpdo_s = self._now
        offset = 0
        for index, sub, bits in self.od.mapped(0x1600 + k):
            size = bits // 8
            self._write(index, sub, data[offset:offset + size], sdo=False)
            offset += size

    def _on_sync(self) -> list[Frame]:
        self.syncs += 1
        for k, data in sorted(self._pending.items()):
            self._apply_rpdo(k, data)
        self._pending.clear()
        self._step_states()
        out = []
        for k in range(4):
            tx_type = self.od.get(0x1800 + k, 2)
            if tx_type > _SYNC_TYPES_MAX or not self._tpdo_on(k):
                continue
            self._sync_counter[k] += 1
            if self._sync_counter[k] >= max(tx_type, 1):
                self._sync_counter[k] = 0
                out.append(self._tpdo(k))
        return out

    def _event_tpdos(self, now_s: float) -> list[Frame]:
        """The event-driven TPDOs due at ``now_s`` (their event timer, or a new statusword)."""
        out = []
        sw = self.od.get(0x6041)
        for k in range(4):
            if self.od.get(0x1800 + k, 2) < _EVENT_TYPES_MIN or not self._tpdo_on(k):
                continue
            timer_ms = self.od.get(0x1800 + k, 5)
            due = timer_ms and now_s - self._tpdo_last_s[k] >= timer_ms / 1000.0 - 1e-9
            mapped_sw = any(i == 0x6041 for i, _, _ in self.od.mapped(0x1A00 + k))
            if due or (mapped_sw and sw != self._tpdo_last_sw[k]):
                out.append(self._tpdo(k))
        return out

    def _tpdo_on(self, k: int) -> bool:
        return self.od.pdo_valid(0x1800 + k)

    def _tpdo(self, k: int) -> Frame:
        self._refresh()
        payload = self.od.pack(0x1A00 + k)
        self._tpdo_last_s[k] = self._now
        self._tpdo_last_sw[k] = self.od.get(0x6041)
        return Frame(self.od.get(0x1800 + k, 1) & 0x7FF, payload)
