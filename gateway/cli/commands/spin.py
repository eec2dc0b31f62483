"""``wheelgate spin``: turn one motor slowly and say what to fix in its configuration.

The edge around :mod:`gateway.apps.spin`: it finds the motor, refuses while a daemon answers on
the configuration's control socket, opens the bus (or, with ``--sim``, a virtual one with the
motor's simulated controller), runs the spin behind the deadman, asks the operator what the
wheel did and prints the verdict.

Exit status: 0 the motor agrees (with ``--no-ask``: the controller agrees, and the verdict
says invert and gear_ratio were not checked by a person); 4
(:data:`~gateway.apps.spin.judge.EXIT_FIX`) something to fix, with the advice; 1 an error (the
motor did not enable, the gateway did not arm it, a daemon or another sender drives the bus,
nothing was measured) or no answer to the question without ``--no-ask`` (standard input
ended, or ``s``: not seen), since then invert and gear_ratio were not checked; 2 bad
usage (an unknown motor, a speed or duration out of bounds) or a configuration that leaves no
spin possible (no speed its controller controls within its limit, no travel to sweep), before
anything is sent; 130 stopped by Ctrl-C (131 Ctrl-\\ or SIGQUIT, 143 SIGTERM, 129 SIGHUP),
after the stop was sent.  Ctrl-Z is a key like any other while the motor may turn (the terminal
is read without its signal characters); SIGTSTP from elsewhere stops the spin, and the command
suspends once the stop is sent.  With ``--json`` the verdict's ``ok`` is true exactly when the
exit status is 0, and an error is a JSON object on stdout (``{"ok": false, "error": {"code",
"message"}}``, as ``status --json``; the message ends saying whether the stop was sent).
"""

from __future__ import annotations

import contextlib
import difflib
import json
import sys
from typing import TYPE_CHECKING, NoReturn

import click

from gateway.apps.spin.deadman import SIGNAL_EXIT, Deadman, suspend
from gateway.apps.spin.judge import (
    NO_MOTION_RATIO,
    described,
    exit_status,
    judge,
    measure,
    parse_seen,
)
from gateway.apps.spin.plan import (
    NoRoomError,
    NoSpinError,
    SpinUsageError,
    describe,
    drive_plan,
    steer_plan,
    way,
)
from gateway.apps.spin.runner import ArmRefusedError, BusInUseError, SpinFailedError, run_spin
from gateway.bus.can_bus import open_bus
from gateway.bus.edge import bus_options
from gateway.cli import FilePath, config_option, json_option
from gateway.cli.commands._common import VIRTUAL_HINT, check_finite, load, socket_for
from gateway.cli.commands._guards import fail_json, fail_json_of
from gateway.core.errors import DriveFaultError, GatewayError, GatewayTimeoutError
from gateway.drive.registry import get_driver_class
from gateway.runtime.client import ClientError, ControlClient
from gateway.sim.bus import SimulatedControllers
from gateway.sim.registry import simulator_for

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

    import can

    from gateway.apps.spin.judge import Measured
    from gateway.apps.spin.plan import SpinPlan
    from gateway.apps.spin.runner import SpinRecord
    from gateway.core.kinematics import Wheel
    from gateway.core.settings import GatewayConfig
    from gateway.core.types import MotorConfig



def motors_by_name(cfg: GatewayConfig) -> dict[str, MotorConfig]:
    """Every motor that spin can turn, by the names it takes: a drive motor's wheel, a
    steering actuator's name (``front steering``, also ``front_steering`` and
    ``front.steering``)."""
    out = {m.wheel: m for m in cfg.motors if m is not None}
    for m in cfg.steering:
        out[m.wheel] = m
        out.setdefault(m.wheel.replace(" ", "_"), m)
        out.setdefault(m.wheel.replace(" ", "."), m)
    return out


def complete_motor(ctx: click.Context, incomplete: str) -> list[str]:
    """Shell completion of MOTOR: the names of the ``-c`` robot's motors (the
    underscore spelling of a steering actuator's); none when it does not load."""
    try:
        cfg = load(ctx, ctx.params.get("config_path"))
    except (GatewayError, click.ClickException):
        return []
    return [n for n in motors_by_name(cfg) if " " not in n and "." not in n
            and n.startswith(incomplete)]


def find_motor(cfg: GatewayConfig, name: str) -> MotorConfig:
    """The motor called ``name``.

    :raises click.BadParameter: naming the nearest name, and listing every one.
    """
    motors = motors_by_name(cfg)
    if name in motors:
        return motors[name]
    known = [m.wheel for m in (*cfg.motors, *cfg.steering) if m is not None]
    close = difflib.get_close_matches(name, list(motors), n=1, cutoff=0.6)
    hint = f"did you mean {close[0]!r}? " if close else ""
    passive = [w.name for w, m in zip(cfg.wheels, cfg.motors, strict=True) if m is None]
    if name in passive:
        hint = f"wheel {name!r} is passive (no motor); "
    raise click.BadParameter(f"{hint}expected a motor of {cfg.name}: "
                             f"{', '.join(repr(k) for k in known)}; got {name!r}",
                             param_hint="MOTOR")


def make_plan(cfg: GatewayConfig, motor: MotorConfig, speed: float | None,
              duration_s: float) -> SpinPlan:
    """The spin of ``motor`` within its limits and the robot's.

    :raises SpinUsageError: for a speed or duration out of bounds.
    :raises NoSpinError: when the configuration leaves no spin of ``motor`` possible (its file
        named first).
    """
    try:
        if motor.steering:
            wheels = [w for w in cfg.wheels if w.name in motor.steers]
            rate = min([motor.max_wheel_rad_s, *(w.max_steer_rate for w in wheels)])
            travel = cfg.geometry.get("max_steer")
            keys = (f"geometry max_steer {travel:g} rad" if isinstance(travel, (int, float))
                    else "its wheels' steer_min and steer_max")
            return steer_plan(motor, speed, duration_s, rate, keys)
        index = [w.name for w in cfg.wheels].index(motor.wheel)
        limit = min(motor.max_wheel_rad_s, cfg.limits.max_wheel_rad_s[index])
        band = get_driver_class(motor.driver)([motor]).uncontrolled_band(0)
        return drive_plan(motor, speed, duration_s, limit, cfg.limits.max_wheel_accel_rad_s2,
                          band)
    except NoSpinError as err:
        raise NoSpinError(f"{cfg.source}: {err}") from err


def refuse_daemon(path: str, robot: str) -> None:
    """Refuse while a daemon answers on its control socket ``path`` (or may: the socket is
    there but cannot be asked), whichever robot it runs (``robot``: the configuration's).

    :raises BusInUseError: naming the socket and the daemon's robot.
    """
    try:
        with ControlClient(path, timeout_s=2.0) as client:
            reply = client.request({"op": "status"})
    except ClientError as err:
        if isinstance(err.__cause__, (FileNotFoundError, ConnectionRefusedError)):
            return  # nothing listens there
        raise BusInUseError(f"cannot tell whether a wheelgate daemon drives the bus: {err}; "
                            f"stop it first (systemctl stop wheelgate)") from err
    running = reply.get("robot", "?")
    other = ("" if running == robot else
             f"; if it drives another robot's bus, name {robot!r}'s own socket with --socket")
    raise BusInUseError(
        f"a wheelgate daemon answers on {path} (robot {running!r}, state "
        f"{reply.get('state', '?')}): it drives the bus, and spin arms the motor itself; stop "
        f"it first (systemctl stop wheelgate), or turn the wheels through it with "
        f"wheelgate jog{other}")


@contextlib.contextmanager
def _bus(cfg: GatewayConfig, motor: MotorConfig, sim: bool
         ) -> Iterator[tuple[can.BusABC, Callable[[], float] | None, str]]:
    """The bus, a probe of the simulated wheel (``--sim``), and the bus's name."""
    interface = "virtual" if sim else cfg.bus.interface
    ctl = None
    probe = None
    if sim:
        device = simulator_for(motor)
        ctl = SimulatedControllers([device], cfg.bus.channel, interface="virtual").start()
        true_angle = (lambda: device.steer_rad) if motor.steering else (
            lambda: device.wheel_position_rad)
        probe = lambda: ctl.snapshot(true_angle)  # noqa: E731 - read under the sim's lock
    try:
        bus = open_bus(interface, cfg.bus.channel, cfg.bus.bitrate, **bus_options(interface, None))
        try:
            yield bus, probe, f"{interface}:{cfg.bus.channel}"
        finally:
            bus.shutdown()
    finally:
        if ctl is not None:
            ctl.shutdown()


def _tty_fd() -> int | None:
    try:
        return sys.stdin.fileno() if sys.stdin is not None and sys.stdin.isatty() else None
    except (OSError, ValueError):  # no real file behind stdin (a test runner's)
        return None


def _ask(plan: SpinPlan, measured: Measured, wheel: Wheel | None) -> tuple[float | None, str]:
    """The operator's answer: what the wheel did over what the encoder measured, and, with
    none, why (``"Ctrl-C"`` when interrupted)."""
    amount = described(plan, measured)
    turned = way(plan, wheel, measured.travel_rad)
    if plan.steering:
        said, unit = f"{amount:.0f} deg {turned} and back", "degrees"
    else:
        said, unit = f"{amount:.2f} turns {turned}", "turns"
    question = (f"The encoder measured {said}. What did {plan.motor.wheel} do? Enter: as "
                f"described; r: the other way; n: it did not turn; s: not seen; or the {unit} "
                f"you saw (negative: the other way) or a factor (4x)")

    def proc(text: str) -> float | None:
        try:
            return parse_seen(text, amount)
        except ValueError as err:
            raise click.BadParameter(str(err)) from err

    try:
        answer: float | None = click.prompt(question, default="", show_default=False,
                                            value_proc=proc, err=True)
    except click.Abort as err:  # end of input, or Ctrl-C at the question
        click.echo("", err=True)
        if isinstance(err.__context__, KeyboardInterrupt):
            return None, "Ctrl-C"
        return None, "no answer: standard input ended"
    return answer, "" if answer is not None else "answered: not seen"


def _truth_seen(record: SpinRecord, measured: Measured | None) -> float | None:
    """With ``--sim``: the simulated wheel's turn over the encoder's (the simulator is the
    one who sees the wheel)."""
    truth = record.truth
    if measured is None or len(truth) < 2 or measured.travel_rad == 0.0:
        return None
    if record.plan.steering:
        turned = max((s.position_rad - truth[0].position_rad for s in truth), key=abs)
    else:
        turned = truth[-1].position_rad - truth[0].position_rad
    return turned / measured.travel_rad


@click.command()
@config_option
@click.argument("motor_name", metavar="MOTOR", shell_complete=lambda ctx, param, incomplete:
                complete_motor(ctx, incomplete))
@click.option("--speed", type=float, default=None,
              help="Wheel speed, rad/s at the wheel (default 1.0); for a steering actuator, "
                   "its steering rate (default 0.3).  At most half the motor's limit.")
@click.option("--duration", type=float, default=3.0, show_default=True,
              help="How long the command lasts, ramps included (s, 1 to 30).")
@click.option("--sim", is_flag=True,
              help="Spin the motor's simulated controller on a virtual bus in this process "
                   "(the simulator then says what the wheel did).")
@click.option("--socket", "socket_path", type=FilePath(dir_okay=False), default=None,
              help="The daemon's control socket to check (default: the configuration's).")
@click.option("--ask/--no-ask", default=True, show_default=True,
              help="Ask what the wheel did (the only check of invert and gear_ratio).  "
                   "--no-ask judges the controller alone (exit 0 when it agrees); without it, "
                   "no answer (end of input) exits 1.")
@json_option
@click.pass_context
def command(ctx: click.Context, config_path: str | None, motor_name: str, speed: float | None,
            duration: float, sim: bool, socket_path: str | None, ask: bool,
            as_json: bool) -> None:
    """Turn one MOTOR (a wheel's name, or a steering actuator's) slowly, compare its motion with
    the command, and say what to fix (invert, gear_ratio, the controller).

    Lift the wheel off the ground.  Any key (Ctrl-Z too) or Ctrl-C stops; the stop (zero and
    disarm) is always sent.  Exit 0: it agrees; 4: something to fix; 1: an error, or no answer
    to the question without --no-ask; 2: bad usage, or a configuration that leaves no spin
    possible; 130: Ctrl-C; 131: Ctrl-\\ (SIGQUIT).  With --json, "ok" is true exactly when
    the exit status is 0.
    """
    try:
        check_finite(duration=duration, **({} if speed is None else {"speed": speed}))
        cfg = load(ctx, config_path)
        motor = find_motor(cfg, motor_name)
        try:
            plan = make_plan(cfg, motor, speed, duration)
        except SpinUsageError as err:
            raise click.BadParameter(str(err), param_hint=err.option) from err
    except (click.ClickException, GatewayError) as err:
        if not as_json:
            raise
        fail_json_of(ctx, err)
    wheel = next((w for w in cfg.wheels if w.name == motor.wheel), None)
    record = _spin(ctx, cfg, motor, plan, wheel, sim, config_path, socket_path, as_json)
    measured = measure(record.plan, record.samples, record.ended_s)
    seen, unchecked = None, ""
    if sim:
        seen = _truth_seen(record, measured)
        unchecked = "" if seen is not None else "the simulator did not say"
    elif record.stopped_by in SIGNAL_EXIT:  # ended by a signal: no question, exit at once
        unchecked = record.stopped_by
    elif measured is not None and not record.fault and abs(measured.ratio) >= NO_MOTION_RATIO:
        seen, unchecked = _ask(record.plan, measured, wheel) if ask else (None, "--no-ask")
    verdict = judge(record.plan, measured, seen, record.fault, record.stopped_by, unchecked)
    signalled = SIGNAL_EXIT.get(record.stopped_by) or SIGNAL_EXIT.get(unchecked) or 0
    status = exit_status(verdict, signalled)
    if as_json:
        click.echo(json.dumps(verdict.as_json(status)))
    else:
        for line in verdict.lines():
            click.echo(line)
        for note in verdict.notes if verdict.judged else ():
            click.echo(f"note: {note}")
    if not signalled and verdict.judged and verdict.ok and status != 0:
        click.echo(f"spin: not checked: invert and gear_ratio of {motor.wheel} ({unchecked}); "
                   f"run spin where you can watch the wheel and answer, or give --no-ask to "
                   f"judge the controller alone", err=True)
    ctx.exit(status)


def _spin(ctx: click.Context, cfg: GatewayConfig, motor: MotorConfig, plan: SpinPlan,
          wheel: Wheel | None, sim: bool, config_path: str | None,
          socket_path: str | None, as_json: bool) -> SpinRecord:
    """Refuse while a daemon answers, then spin on the bus; the stop line once it is sent (an
    error: :func:`_failed`, once the bus is closed)."""
    deadman: Deadman | None = None
    try:
        if not sim:
            refuse_daemon(socket_for(ctx, config_path, socket_path), cfg.name)
            if cfg.bus.interface == "virtual":
                click.echo(f"spin: note: python-can's virtual bus exists only inside this "
                           f"process, so only simulators in it answer (--sim); {VIRTUAL_HINT}",
                           err=True)
        tty_fd = _tty_fd()
        with _bus(cfg, motor, sim) as (bus, probe, where):
            header = (f"{motor.wheel} ({motor.driver} node {motor.node_id}) on {where}: "
                      f"{describe(plan, wheel)}.  "
                      f"{'Any key (Ctrl-Z too) or ' if tty_fd is not None else ''}"
                      f"Ctrl-C stops; the stop is always sent.")
            with Deadman(tty_fd) as deadman:
                record = run_spin(bus, plan, deadman, rate_hz=cfg.loop.rate_hz,
                                  enable_timeout_s=cfg.loop.enable_timeout_s,
                                  watchdog=cfg.loop.controller_watchdog,
                                  can_ids=cfg.loop.can_ids, probe=probe, header=header,
                                  announce=lambda line: click.echo(f"spin: {line}", err=True))
    except GatewayError as err:  # (a SIGTSTP came first: suspend once the error is said)
        _failed(ctx, err, as_json, deadman is not None and deadman.suspend_asked)
    if record.stop:
        click.echo(f"spin: stop sent (zero and disarm) after {record.ended_s:.1f} s"
                   f"{f', stopped by {record.stopped_by}' if record.stopped_by else ''}",
                   err=True)
    else:
        click.echo(f"spin: stopped by {record.stopped_by} before anything was sent", err=True)
    if deadman.suspend_asked:  # stopped, terminal restored: now as SIGTSTP would have
        suspend()
    return record


def _failed(ctx: click.Context, err: GatewayError, as_json: bool,
            suspend_after: bool) -> NoReturn:
    """An error of the spin, then whether the stop was sent (a refusal sent nothing), then,
    when a SIGTSTP came before the error, the suspension; with ``--json`` a JSON error object
    on stdout (``status --json``'s, whose message says the same).  Exit 1."""
    cause = err.cause if isinstance(err, SpinFailedError) else err
    after = ("spin: stop sent (zero and disarm) after the error"
             if isinstance(err, SpinFailedError) else
             "spin: nothing was sent" if isinstance(cause, BusInUseError) else "")
    if not as_json:
        click.echo(f"Error: {err}", err=True)
    if after:
        click.echo(after, err=True)
    if suspend_after:
        suspend()
    if as_json:
        code = ("bus_in_use" if isinstance(cause, BusInUseError) else
                "not_armed" if isinstance(cause, ArmRefusedError) else
                "fault" if isinstance(cause, DriveFaultError) else
                "not_enabled" if isinstance(cause, GatewayTimeoutError) else
                "no_room" if isinstance(cause, NoRoomError) else "error")
        said = f"; {after.removeprefix('spin: ')}" if after else ""
        fail_json(ctx, code, message=f"{err}{said}")
    ctx.exit(1)
