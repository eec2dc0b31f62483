"""The motors of one robot grouped by protocol: one driver instance per driver name.

:class:`DriveSet` is what the loop and the CLI talk to: it takes every wheel's speed in model
order, hands each driver the speeds of its own motors and returns all frames of the cycle in
one list (moteus' "build all, then send once"), so no two wheels act on commands from different
cycles.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from gateway.registry import get_driver_class

if TYPE_CHECKING:
    from collections.abc import Sequence

    from gateway.config import GatewayConfig
    from gateway.driver import MotorDriver
    from gateway.sim import DeviceSimulator
    from gateway.types import Frame, MotorStatus, WheelFeedback


class DriveSet:
    """Every driven wheel's driver.

    :param config: the validated configuration.
    :raises DriverNotFoundError: if a driver cannot be loaded.
    """

    def __init__(self, config: GatewayConfig) -> None:
        self.config = config
        groups: dict[str, list[int]] = {}
        for i, motor in enumerate(config.motors):
            if motor is not None:
                groups.setdefault(motor.driver, []).append(i)
        #: (driver, wheel indices in model order) pairs.
        self.groups: tuple[tuple[MotorDriver, tuple[int, ...]], ...] = tuple(
            (
                get_driver_class(name)(
                    [m for m in (config.motors[i] for i in idx) if m is not None]
                ),
                tuple(idx),
            )
            for name, idx in groups.items()
        )
        #: Whether any driver closes its speed loop on the host (see MotorDriver).
        self.host_speed_loop = any(drv.HOST_SPEED_LOOP for drv, _ in self.groups)
        flat = [i for _, idx in self.groups for i in idx]
        self._whole = len(self.groups) == 1 and flat == list(range(len(config.motors)))
        #: Positions in the drivers' concatenated status that give model order (``None``:
        #: already in model order), so :meth:`status` needs no sort per cycle.
        self._status_order: tuple[int, ...] | None = (
            None if flat == sorted(flat) else tuple(sorted(range(len(flat)), key=flat.__getitem__))
        )

    def _split(self, wheel_rad_s: Sequence[float]) -> list[Sequence[float]]:
        if self._whole and len(wheel_rad_s) == len(self.config.motors):
            return [wheel_rad_s]  # one driver for every wheel, in model order: nothing to split
        return [[wheel_rad_s[i] for i in idx] for _, idx in self.groups]

    def enable(self, now_s: float) -> list[Frame]:
        """Enable frames of every driver."""
        return [f for drv, _ in self.groups for f in drv.enable(now_s)]

    def disable(self, now_s: float) -> list[Frame]:
        """Zero-speed and disarm frames of every driver."""
        return [f for drv, _ in self.groups for f in drv.disable(now_s)]

    def command(self, wheel_rad_s: Sequence[float], now_s: float) -> list[Frame]:
        """This cycle's velocity frames for every wheel (model order, rad/s)."""
        out: list[Frame] = []
        for (drv, _), speeds in zip(self.groups, self._split(wheel_rad_s), strict=True):
            out.extend(drv.command(speeds, now_s))
        return out

    def preview(self, wheel_rad_s: Sequence[float]) -> list[Frame]:
        """The velocity frames for these speeds with every driver freshly enabled and no
        feedback (what ``wheelgate frames`` prints)."""
        out: list[Frame] = []
        for (drv, _), speeds in zip(self.groups, self._split(wheel_rad_s), strict=True):
            out.extend(drv.preview_command(speeds))
        return out

    def poll(self, now_s: float) -> list[Frame]:
        """Housekeeping frames of every driver."""
        return [f for drv, _ in self.groups for f in drv.poll(now_s)]

    def on_frame(self, frame: Frame) -> bool:
        """Give a received frame to the driver it belongs to."""
        for drv, _ in self.groups:
            if drv.on_frame(frame):
                return True
        return False

    def status(self, now_s: float) -> list[MotorStatus]:
        """Every motor's status, in model order of their wheels."""
        out: list[MotorStatus] = []
        for drv, idx in self.groups:
            statuses = drv.status(now_s)
            if len(statuses) != len(idx):
                raise ValueError(
                    f"{type(drv).__name__}.status returned {len(statuses)} motors, "
                    f"expected {len(idx)}"
                )
            out.extend(statuses)
        order = self._status_order
        return out if order is None else [out[k] for k in order]

    def feedback_by_wheel(self) -> list[WheelFeedback | None]:
        """The latest feedback of every wheel in model order (``None``: passive or none yet)."""
        out: list[WheelFeedback | None] = [None] * len(self.config.motors)
        for drv, idx in self.groups:
            for k, i in enumerate(idx):
                out[i] = drv.feedback(k)
        return out

    def simulators(self) -> list[DeviceSimulator]:
        """A device simulator for every motor."""
        return [drv.make_simulator(m) for drv, _ in self.groups for m in drv.motors]
