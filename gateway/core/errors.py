"""The one error tree of wheelgate.

Every error that wheelgate raises on purpose derives from :class:`GatewayError`.  Categories
also subclass the matching built-in, so callers that only know Python's exceptions still catch
them::

    GatewayError
     +-- ConfigError (ValueError)             file + key path in the message
     +-- DriverNotFoundError (LookupError)    lists the valid names
     +-- BusError                             wraps can.CanError (``raise ... from err``)
     +-- EncodeError (ValueError)             entity + expected + got
     +-- DecodeError (ValueError)             entity + expected + got
     +-- GatewayTimeoutError (TimeoutError)
     +-- DriveFaultError                      carries node_id and DriveFault flags
     +-- IllegalTransitionError               a drive state change that the table forbids
     +-- KinematicsError (ValueError)         a geometry the model cannot use
          +-- InfeasibleTwistError            a twist the wheels cannot follow without slip

Messages name the entity, what was expected and what came.  An optional ``error_code`` is
appended as ``[Error Code N]``, as python-can's ``CanError`` does.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from gateway.core.types import DriveFault, Twist


class GatewayError(Exception):
    """Root of every wheelgate error.

    :param message: what went wrong, naming the entity, what was expected and what came.
    :param error_code: optional numeric code, appended to the message.
    """

    def __init__(self, message: str = "", error_code: int | None = None) -> None:
        self.error_code = error_code
        if error_code is not None:
            message = f"{message} [Error Code {error_code}]"
        super().__init__(message)


class ConfigError(GatewayError, ValueError):
    """A configuration file or value is wrong; the message gives the file and key path.

    One error may carry several problems (every one a file's check found): the message has
    one line per problem, and :attr:`problems` holds them apart.

    >>> err = ConfigError.of(["a.yaml: name: expected str, got 1", "a.yaml: drive: missing"])
    >>> err.problems[1]
    'a.yaml: drive: missing'
    >>> print(err)
    a.yaml: name: expected str, got 1
    a.yaml: drive: missing
    """

    _problems: tuple[str, ...] = ()

    @property
    def problems(self) -> tuple[str, ...]:
        """Each problem's message (one, unless made by :meth:`of`)."""
        return self._problems or (str(self),)

    @classmethod
    def of(cls, problems: list[str] | tuple[str, ...]) -> ConfigError:
        """One error for several problems, one line each."""
        err = cls("\n".join(problems))
        err._problems = tuple(problems)
        return err


class DriverNotFoundError(GatewayError, LookupError):
    """No driver is registered under the requested name; the message lists the valid names."""


class BusError(GatewayError):
    """The CAN bus refused an operation (wraps :class:`can.CanError`)."""


class EncodeError(GatewayError, ValueError):
    """A value cannot be put on the wire (out of range, not finite, wrong type)."""


class DecodeError(GatewayError, ValueError):
    """A frame that belongs to a codec is malformed (wrong DLC, wrong ID type, bad value)."""


class GatewayTimeoutError(GatewayError, TimeoutError):
    """Something did not happen within its deadline."""


class DriveFaultError(GatewayError):
    """A motor controller reports a fault.

    :param node_id: the controller's node ID.
    :param faults: the fault flags it reported.
    """

    def __init__(self, message: str, node_id: int, faults: DriveFault) -> None:
        super().__init__(message)
        self.node_id = node_id
        self.faults = faults


class IllegalTransitionError(GatewayError):
    """A drive state change that the protocol's transition table does not allow."""


class KinematicsError(GatewayError, ValueError):
    """A wheel layout or kinematic query that the model cannot handle."""


class InfeasibleTwistError(KinematicsError):
    """A twist breaks a no-slip constraint or a steering limit.

    :param wheel: name of the wheel whose constraint is violated.
    :param constraint: which constraint, e.g. ``"sliding"`` or ``"steering limit"``.
    :param residual_m_s: the constraint violation as a sliding speed, m/s.
    :param nearest: the nearest twist the robot can follow (least-squares projection).
    :param twist: the twist that was asked for.
    """

    def __init__(
        self,
        wheel: str,
        constraint: str,
        residual_m_s: float,
        nearest: Twist,
        twist: Twist,
        detail: str = "",
    ) -> None:
        self.wheel = wheel
        self.constraint = constraint
        self.residual_m_s = residual_m_s
        self.nearest = nearest
        self.twist = twist
        text = (
            f"Twist {twist} is infeasible: wheel {wheel!r} breaks its {constraint} constraint "
            f"by {residual_m_s:.4g} m/s"
        )
        if detail:
            text += f" ({detail})"
        text += f"; nearest feasible twist is {nearest}"
        super().__init__(text)
