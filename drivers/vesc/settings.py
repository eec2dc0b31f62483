"""What a configuration states about a VESC's own settings, which wheelgate cannot write.

A VESC's command timeout, its CAN status messages and its minimum ERPM live in its app and
motor configurations, written as a whole by VESC Tool (``COMM_SET_APPCONF`` and
``COMM_SET_MCCONF``, ``comm/commands.c`` in https://github.com/vedderb/bldc, read at
``b9d287b3``), not by a simple CAN command.  The motor block states them
(:class:`VescOptions`); the timeout is read back while enabling (:mod:`drivers.vesc.readback`):

* ``controller_timeout_s``: App Settings > General > Timeout (``timeout_msec``; 1000 ms from
  the factory), after which ``timeout_thread`` (``timeout.c``) releases the motor and brakes
  with ``timeout_brake_current`` (0 A from the factory: the motor coasts);
* ``status_rate_hz``: App Settings > General > Can Status Rate 1 (``can_status_rate_1``, 50 Hz
  from the factory), with Status 1 and Status 5 ticked in Can Messages Rate 1
  (``can_status_msgs_r1``, bits 0 and 4; 0, no status at all, from the factory; the FOC setup
  wizard, ``conf_general_detect_apply_all_foc_can`` in ``conf_general.c``, sets it to
  ``0b00001111``: Status 1 to 4, without STATUS_5);
* ``min_erpm``: Motor Settings > PID Controllers > Minimum ERPM (``s_pid_min_erpm``, 900 from
  the factory; :mod:`drivers.vesc.min_erpm`).

Factory values: ``APPCONF_TIMEOUT_MSEC``, ``APPCONF_TIMEOUT_BRAKE_CURRENT``,
``APPCONF_CAN_STATUS_RATE_1``, ``APPCONF_CAN_STATUS_MSGS_R1`` in
``applications/appconf_default.h``; ``MCCONF_S_PID_MIN_RPM`` in ``motor/mcconf_default.h`` (a
board's ``hwconf`` may override them).  ``controller_timeout_s`` and ``status_rate_hz`` default
to 0, "not stated": an unstated timeout is a warning (:meth:`VescDriver.protection`), and a
simulator built from the block has the factory's timeout and sends no status.  ``min_erpm``
defaults to the factory value: state it only if you changed it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, TypeVar

from drivers.vesc.min_erpm import FACTORY_MIN_ERPM
from gateway.core.errors import ConfigError
from gateway.drive.options import (
    CONTROLLER_TIMEOUT_OPTION,
    StatedTimeout,
    option,
    spec_field,
)

if TYPE_CHECKING:
    from collections.abc import Mapping

__all__ = [
    "FACTORY_STATUS_MSGS",
    "FACTORY_STATUS_RATE_HZ",
    "FACTORY_TIMEOUT_S",
    "STATUS_1",
    "STATUS_5",
    "TIMEOUT_ACTION",
    "TIMEOUT_FIX",
    "UNSTATED_HOW",
    "VescOptions",
    "missing_status",
]

_O = TypeVar("_O", bound="VescOptions")

#: ``timeout_msec`` from the factory (s).
FACTORY_TIMEOUT_S = 1.0
#: ``can_status_rate_1`` from the factory (Hz); ``can_status_msgs_r1`` is 0, so none is sent.
FACTORY_STATUS_RATE_HZ = 50.0
#: ``can_status_msgs_r1`` bit of STATUS (Status 1 in VESC Tool).
STATUS_1 = 1 << 0
#: ``can_status_msgs_r1`` bit of STATUS_5 (Status 5 in VESC Tool).
STATUS_5 = 1 << 4
#: ``can_status_msgs_r1`` from the factory: no status messages.
FACTORY_STATUS_MSGS = 0

#: Where a VESC's status messages are switched on, for the messages about missing ones.
STATUS_WHERE = "VESC Tool, App Settings > General > Can Messages Rate 1"
#: How to switch each status stream on (the driver's :attr:`STREAM_HINTS`).
STREAM_HINTS: Mapping[str, str] = MappingProxyType({
    "STATUS": f"tick Status 1 in {STATUS_WHERE}",
    "STATUS_5": f"tick Status 5 in {STATUS_WHERE} (the motor setup wizard ticks Status 1 to 4 "
                f"only)",
})


@dataclass(frozen=True, kw_only=True)
class VescOptions(StatedTimeout):
    """The protocol keys of a VESC motor block.

    :param pole_pairs: motor pole pairs; eRPM = RPM * pole pairs.
    :param command_period_s: the keep-alive: the last command is resent at least this often.
    :param controller_timeout_s: the VESC's own timeout, as set in VESC Tool (0: not stated).
    :param status_rate_hz: the rate of STATUS and STATUS_5 set in VESC Tool (0: not stated).
    :param min_erpm: ``s_pid_min_erpm``: below it the VESC does not speed-control.
    :param liveness_s: a status stream older than this makes the motor OFFLINE.
    """

    liveness_s: float = spec_field(
        dataclasses.replace(StatedTimeout.specs()["liveness_s"],
                            help="status frames older than this: OFFLINE (s)")
    )
    controller_timeout_s: float = spec_field(
        dataclasses.replace(
            CONTROLLER_TIMEOUT_OPTION,
            help="the VESC's own command timeout as set in VESC Tool, App Settings > General > "
            "Timeout (s; 1 s from the factory), after which it releases the motor; read back "
            "over CAN while enabling; 0: not stated",
        )
    )
    pole_pairs: int = option(
        int, minimum=1, help="motor pole pairs (poles / 2); eRPM = RPM * pole_pairs"
    )
    command_period_s: float = option(
        float,
        0.02,
        minimum=0.001,
        help="resend the last command at least this often (s); less than half the VESC's "
        "timeout (controller_timeout_s, else the factory 1 s)",
    )
    status_rate_hz: float = option(
        float,
        0.0,
        minimum=0.0,
        maximum=10000.0,
        help="the rate set in VESC Tool for STATUS and STATUS_5, App Settings > General > "
        "Can Status Rate 1 (Hz), with Status 1 and Status 5 ticked in Can Messages Rate "
        "1; 0: not stated (a factory VESC sends none)",
    )
    min_erpm: float = option(
        float,
        FACTORY_MIN_ERPM,
        minimum=0.0,
        help="s_pid_min_erpm, VESC Tool: Motor Settings > PID Controllers > Minimum ERPM "
        "(900 from the factory; state it if you changed it): below it the VESC does not "
        "speed-control the motor",
    )

    @property
    def timeout_s(self) -> float:
        """The VESC's timeout (s): the stated one, else the factory's."""
        return self.controller_timeout_s or FACTORY_TIMEOUT_S

    @classmethod
    def validate(cls, raw: Mapping[str, object], where: str) -> dict[str, object]:
        """The keys checked one by one (:meth:`from_block` and
        :meth:`~drivers.vesc.driver.VescDriver.validate_options` check them against each
        other).

        :raises ConfigError: for an unknown, missing or bad key (``timeout_s`` with its new
            name).
        """
        if "timeout_s" in raw:
            raise ConfigError(
                f"{where}.timeout_s: renamed controller_timeout_s (the timeout set in VESC Tool, "
                f"App Settings > General > Timeout, in s)"
            )
        return super().validate(raw, where)

    @classmethod
    def from_block(cls: type[_O], raw: Mapping[str, object], where: str) -> _O:
        """The options of a motor block, checked one by one and against each other.

        :raises ConfigError: as :meth:`validate` and :meth:`check`.
        """
        opts = super().from_block(raw, where)
        opts.check(where)
        return opts

    def check(self, where: str) -> None:
        """Check the keys against each other.

        :raises ConfigError: for a keep-alive period not less than half the VESC's timeout (the
            stated one, else the factory 1 s), or a liveness time shorter than two periods of
            the stated status rate.
        """
        period, stated, timeout = self.command_period_s, self.controller_timeout_s, self.timeout_s
        if not period < timeout / 2.0:
            whose = (
                f"controller_timeout_s {stated:g} s" if stated
                else f"the factory {FACTORY_TIMEOUT_S:g} s, as controller_timeout_s is not stated"
            )
            raise ConfigError(
                f"{where}.command_period_s: expected less than half the VESC's timeout ({whose}) "
                f"= {timeout / 2:g} s (one lost frame must not let the VESC release the motor), "
                f"got {period!r}"
            )
        rate, liveness = self.status_rate_hz, self.liveness_s
        if rate and liveness < 2.0 / rate:
            raise ConfigError(
                f"{where}.liveness_s: expected at least two status periods at status_rate_hz "
                f"{rate:g} ({2.0 / rate:g} s), or one late frame makes the motor OFFLINE; got "
                f"{liveness!r}"
            )


#: What a VESC does when its timeout expires (``timeout.c``: ``timeout_thread``).
TIMEOUT_ACTION = "releases the motor: it coasts (timeout_brake_current 0 A)"
#: How to get a stated timeout.
TIMEOUT_FIX = (
    "set App Settings > General > Timeout in VESC Tool (1000 ms from the factory; 0 turns it "
    "off) and state it as controller_timeout_s, e.g. controller_timeout_s: 1.0"
)
#: What is known of an unstated timeout.
UNSTATED_HOW = (
    "not stated: a VESC releases its motor after App Settings > General > Timeout (1000 ms "
    "from the factory, 0: never), which wheelgate reads back from the VESC while enabling"
)


def missing_status(status_seen: bool, status5_seen: bool) -> str:
    """What a motor has never sent and how to switch it on ("" if it has sent both)."""
    if not status_seen and not status5_seen:
        return (
            f"no STATUS or STATUS_5 received: a VESC sends CAN status only when enabled in "
            f"VESC Tool (none from the factory): tick Status 1 and Status 5 in {STATUS_WHERE}, "
            f"set Can Status Rate 1 (e.g. 50 Hz), and state it as status_rate_hz"
        )
    if not status5_seen:
        return f"no STATUS_5 received (the tachometer, for odometry): {STREAM_HINTS['STATUS_5']}"
    if not status_seen:
        return f"no STATUS received (the speed): {STREAM_HINTS['STATUS']}"
    return ""
