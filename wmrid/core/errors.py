"""The exception hierarchy of wmrid and the exit codes it maps to.

Every error a user can cause derives from :class:`WmridError`; the CLI maps the class to an exit code
in one place (``wmrid.cli.app``) and prints the message as one line on stderr.
"""

from __future__ import annotations

import contextlib
import contextvars
import errno
from collections.abc import Iterator
from enum import IntEnum


class ExitStatus(IntEnum):
    OK = 0
    NO_RESULT = 1  # the log does not support a result (e.g. no excitation)
    USAGE = 2  # bad usage or unreadable input
    INTERRUPTED = 130


class WmridError(Exception):
    """Base class of every error wmrid reports to a user.

    The command line maps the class to an exit code in one place (``wmrid.cli.app``) and prints the message as one
    line on stderr.

    Attributes
    ----------
    exit_status
        The exit code of the command line for this error: 2 (bad usage or unreadable input); 1 for
        :class:`NotIdentifiableError`, :class:`StreamError` and :class:`OutputWriteError`.
    """

    exit_status = ExitStatus.USAGE


class UsageError(WmridError, ValueError):
    """An option or argument that cannot be used as given."""


class RobotFileError(WmridError, ValueError):
    """A robot description that cannot be read or is not physically valid."""


class LogFormatError(WmridError, ValueError):
    """A log file that cannot be read, or lacks what identification needs."""


class OutputExistsError(WmridError, FileExistsError):
    """An output file already exists and ``--force`` was not given."""


class NotIdentifiableError(WmridError):
    """The log does not excite the dynamics enough to give any result."""

    exit_status = ExitStatus.NO_RESULT


class StreamError(WmridError):
    """A live source that broke off: a connection lost or refused, a server that stopped answering or sent malformed
    frames.  ``wmrid live`` keeps what it received before (its result is written) and exits 1."""

    exit_status = ExitStatus.NO_RESULT


class OutputWriteError(WmridError):
    """An output could not be written (a full disk, a closed or failing stream); nothing partial stands as complete."""

    exit_status = ExitStatus.NO_RESULT


def cannot_read(err: OSError) -> str:
    """Why a file could not be opened, with the fix, for a message after its name: "cannot be read (Permission
    denied); check its permissions", "cannot be read (No such file or directory); check the path"."""
    why = err.strerror or str(err)
    fix = {errno.EACCES: "check its permissions", errno.EPERM: "check its permissions", errno.ENOENT: "check the path",
           errno.EISDIR: "give a file", errno.ELOOP: "fix the link"}.get(err.errno or 0)  # fmt: skip
    return f"cannot be read ({why})" + (f"; {fix}" if fix else "")


class ReaderGone(Exception):
    """The reader of standard output (``| head``) closed the pipe: not an error, the run ends with exit 0.  Not an
    OSError, so that Click does not turn it into exit 1 on its way out."""


# --------------------------------------------------------------------------------------------------
# Options named as the caller knows them

#: How :func:`option` names an option: "python" (a keyword argument, the library's default) or "flag" (the command
#: line's, set by :func:`wmrid.cli.app.main` while a command runs).
_OPTION_STYLE: contextvars.ContextVar[str] = contextvars.ContextVar("wmrid_option_style", default="python")

#: Flags whose name is not the keyword argument's with dashes.
FLAG_NAMES = {
    "output_format": "--format", "log": "LOG", "input_": "INPUT", "calibration_s": "--calibration",
    "eta_std": "--eta-noise", "tau_std": "--tau-noise", "caster_std": "--caster",
}  # fmt: skip


def option(name: str, value: object = ...) -> str:
    """An option as the caller gave it, for a message: ``friction='wheel+caster'`` to a library caller,
    ``--friction wheel+caster`` on the command line (:func:`option_style`); ``value=True``: a switch (``force=True``,
    ``--force``)."""
    if _OPTION_STYLE.get() == "flag":
        flag = FLAG_NAMES.get(name, "--" + name.replace("_", "-"))
        return flag if value is ... or value is True else f"{flag} {value}"  # a switch: the flag alone
    return name if value is ... else f"{name}={value!r}"


@contextlib.contextmanager
def option_style(style: str) -> Iterator[None]:
    """Name options in messages as ``style`` ("python" or "flag") inside the block."""
    token = _OPTION_STYLE.set(style)
    try:
        yield
    finally:
        _OPTION_STYLE.reset(token)
