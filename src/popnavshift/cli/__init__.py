"""The ``popnavshift`` command line: one dispatcher, one subcommand per stage.

User errors (:class:`PopNavShiftError`), usage errors (a bad option value, a
missing argument) and the operating system's refusals (a full disk, permissions, a
path that is missing or of the wrong kind) become one red line and exit code 2;
``--verbose`` adds the traceback and shows the log (retries, re-asks). Every text from
the user or a server is escaped before rich renders it (control characters as their
codes, :func:`.app.printable`), and redacted
(:mod:`popnavshift.redact`). Everything else is a bug and shows a traceback.
Commands live in :mod:`.population` (personas → populations), :mod:`.simulation`
(episodes, simulate, replay, bench), :mod:`.plan`, :mod:`.study` (run, report), :mod:`.calibrate`,
:mod:`.evaluate` (evaluate, compare), :mod:`.data` (show-prompt, describe) and :mod:`.audit`
(the respondent audit). Those modules import only typer, rich and the first layer at their
top, and each command what it needs when it runs, so that ``--help``, ``--version`` and a
usage error start at once (tests/test_cli_startup.py checks it).
"""

from __future__ import annotations

import errno
import sqlite3
import sys
from typing import NoReturn

import typer

from ..errors import PopNavShiftError
from ..progress import console
from . import (  # noqa: F401  (register the commands)
    audit,
    calibrate,
    data,
    evaluate,
    plan,
    population,
    simulation,
    study,
)
from .app import STATE, app, print_traceback, reflow_help, say

reflow_help(app)

INTERRUPTED = "[yellow]interrupted[/]: finished work is kept; run the same command to resume"


def main() -> None:
    """Entry point: run the app, turning user and usage errors into one line, exit 2."""
    try:
        result = app(standalone_mode=False, prog_name="popnavshift")
    except PopNavShiftError as exc:
        if STATE["verbose"]:
            print_traceback()
        fail(str(exc))
    except (OSError, sqlite3.OperationalError) as exc:  # the machine said no: not a bug
        if STATE["verbose"]:
            print_traceback()
        fail(os_error_line(exc))
    except _INTERRUPTS:
        result = 130
    except _USAGE_ERRORS as exc:
        _usage_error(exc)
    except typer.Exit as exc:
        sys.exit(exc.exit_code)
    if result == 130:  # typer returns 130 when Ctrl-C interrupted a command
        console.print(INTERRUPTED)
        sys.exit(130)
    if isinstance(result, int) and result:  # a command's typer.Exit(code), returned here
        sys.exit(result)


def fail(message: str) -> NoReturn:
    """Print one red ``error:`` line (escaped, redacted) and exit with code 2."""
    one_line = " ".join(message.split())
    console.print(f"[bold red]error:[/] {say(one_line)}", highlight=False, soft_wrap=True)
    sys.exit(2)


#: what to do about the usual refusals of the operating system
_OS_HINTS = {
    errno.ENOSPC: "free some space or choose another --out",
    errno.EDQUOT: "free some space or choose another --out",
    errno.EACCES: "check the permissions, or choose another folder",
    errno.EPERM: "check the permissions, or choose another folder",
    errno.EROFS: "the file system is read-only: choose another folder",
    errno.ENOENT: "check the path",
    errno.EISDIR: "give a file, not a folder",
    errno.ENOTDIR: "a part of the path is a file, not a folder",
    errno.ENAMETOOLONG: "use a shorter name",
}


def os_error_line(exc: BaseException) -> str:
    """One line for an error of the operating system (full disk, permissions, a missing or
    wrong kind of path, a locked or full SQLite file): what failed, where, and a hint."""
    if isinstance(exc, sqlite3.OperationalError):
        return f"the response cache failed: {exc} (check the free space and permissions)"
    assert isinstance(exc, OSError)
    what = exc.strerror or type(exc).__name__
    where = " → ".join(str(f) for f in (exc.filename, exc.filename2) if f is not None)
    hint = _OS_HINTS.get(exc.errno or 0)
    text = f"{where}: {what}" if where else f"{what} ({exc})" if str(exc) != what else what
    return f"{text} ({hint})" if hint else text


def _usage_errors() -> tuple[tuple[type[BaseException], ...], tuple[type[BaseException], ...]]:
    """(usage errors, aborts) of the installed typer: recent typer vendors its own click
    (``typer._click``, whose exceptions derive from ``typer.TyperException``), older
    ones raise click's; catch both so a usage error is never a traceback. An older typer
    has imported click already; a recent one does not, and importing it would only slow
    the start."""
    usage: list[type[BaseException]] = [typer.TyperException]
    aborts: list[type[BaseException]] = [typer.Abort]
    click = sys.modules.get("click")
    if click is not None:
        usage.append(click.exceptions.ClickException)
        aborts.append(click.exceptions.Abort)
    return tuple(usage), tuple(aborts)


_USAGE_ERRORS, _ABORTS = _usage_errors()
_INTERRUPTS: tuple[type[BaseException], ...] = (KeyboardInterrupt, *_ABORTS)


def _usage_error(exc: BaseException) -> NoReturn:
    if type(exc).__name__ == "NoArgsIsHelpError":  # `popnavshift run` with no args: help
        exc.show()  # type: ignore[attr-defined]
        sys.exit(2)
    ctx = getattr(exc, "ctx", None)
    where = f"{ctx.command_path}: " if ctx is not None else ""
    text = exc.format_message() if hasattr(exc, "format_message") else str(exc)
    hint = f" (see {ctx.command_path} --help)" if ctx is not None else ""
    fail(f"{where}{text}{hint}")
