"""The driver contract's part of controller-side protection (:mod:`gateway.core.protection`):
the default for protocols whose timeout is stated, and the text of a protection fault."""

from __future__ import annotations

from gateway.core.protection import Guard, Protection


def stated_protection(protocol: str, action: str, fix: str, stated_s: float) -> Protection:
    """The protection of a motor whose controller's timeout cannot be set over CAN:
    :attr:`Guard.STATED` by its ``controller_timeout_s`` (``stated_s`` > 0), else
    :attr:`Guard.UNSTATED` with ``fix``.

    :param protocol: the protocol's name, for the message.
    :param action: what the controller does when the timeout expires.
    :param fix: how to set and state the timeout.
    """
    if stated_s > 0:
        return Protection(
            Guard.STATED,
            float(stated_s),
            action,
            "set on the controller outside wheelgate; stated by controller_timeout_s "
            "(not verifiable over CAN)",
        )
    return Protection(
        Guard.UNSTATED,
        None,
        "unknown",
        f"not stated: nothing known stops this {protocol} motor if wheelgate dies",
        fix,
    )


def fault_text(wheel: str, protocol: str, node_id: int, why: str, fix: str) -> str:
    """The text of a protection that was not confirmed: the motor, what came back, the fix."""
    return (
        f"motor {wheel!r} ({protocol} node {node_id}): controller watchdog not confirmed: "
        f"{why}" + (f"; fix: {fix}" if fix else "")
    )
