"""The systemd unit ``wheelgate init --unit`` writes: the shipped one, with ``ExecStart=`` naming
the ``wheelgate`` that wrote it (the shipped unit names ``/opt/wheelgate/venv/bin/wheelgate``,
the README's installation).  Pure: the path comes in, the text goes out."""

from __future__ import annotations

#: The start of the shipped unit's line that starts the daemon.
EXEC_START = "ExecStart="
#: The program the shipped unit starts.
SHIPPED_PROGRAM = "/opt/wheelgate/venv/bin/wheelgate"


def quoted(path: str) -> str:
    """``path`` as one word of a systemd command line: ``%`` doubled (systemd's specifiers),
    and in double quotes, with ``\\`` and ``"`` escaped, if it holds white space or a quote
    (systemd.service(5), "Command lines").

    >>> quoted("/opt/wg/bin/wheelgate"), quoted("/home/a b/bin/wheelgate")
    ('/opt/wg/bin/wheelgate', '"/home/a b/bin/wheelgate"')
    """
    word = path.replace("%", "%%")
    if any(c.isspace() or c in "\"'\\" for c in word):
        word = '"' + word.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return word


def unit_text(shipped: str, program: str | None) -> str:
    """The shipped unit with its ``ExecStart=`` starting ``program`` (an absolute path of the
    ``wheelgate`` console script), and a comment saying so; the shipped unit as it is when
    ``program`` is ``None`` (not known) or the shipped one.

    :raises ValueError: if the shipped unit has no ``ExecStart=`` line naming
        :data:`SHIPPED_PROGRAM`, or ``program`` is not absolute.
    """
    if program is None or program == SHIPPED_PROGRAM:
        return shipped
    if not program.startswith("/"):
        raise ValueError(f"expected an absolute path of wheelgate, got {program!r}")
    lines = shipped.splitlines(keepends=True)
    at = next((i for i, line in enumerate(lines)
               if line.startswith(EXEC_START + SHIPPED_PROGRAM + " ")), None)
    if at is None:
        raise ValueError(f"the shipped unit has no line {EXEC_START}{SHIPPED_PROGRAM} ...")
    rest = lines[at][len(EXEC_START + SHIPPED_PROGRAM):]
    note = (f"# The wheelgate that wrote this unit (wheelgate init --unit); the shipped\n"
            f"# unit names {SHIPPED_PROGRAM}.\n")
    lines[at:at + 1] = [note, EXEC_START + quoted(program) + rest]
    return "".join(lines)
