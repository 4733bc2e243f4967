"""The ``popnavshift`` command line: one dispatcher, one subcommand per stage.

User errors (:class:`PopNavShiftError`) and usage errors (a bad option value, a
missing argument) become one red line and exit code 2; ``--verbose`` adds the
traceback of a user error and shows the log (retries, re-asks). Every text from
the user or a server is escaped before rich renders it, and redacted
(:mod:`popnavshift.redact`). Everything else is a bug and shows a traceback.
Commands live in :mod:`.population` (personas → populations), :mod:`.simulation`
(episodes, simulate, replay, bench) and :mod:`.study` (plan, run, report).
"""

from __future__ import annotations

import logging
import math
import os
import sys
from pathlib import Path
from typing import Annotated, Any, NoReturn

import typer
from rich.markup import escape

from .. import __version__
from ..errors import ConfigError, PopNavShiftError
from ..progress import console
from ..redact import RedactingFilter, redact

app = typer.Typer(
    name="popnavshift",
    help=(
        "Stress-test social robot navigation under behavioral population shift.\n\n"
        "Pipeline: personas → probe responses → motion profiles → populations → "
        "episodes → navground runs → analysis → report. Each stage reads and writes a "
        "study folder; `popnavshift run` does all of it."
    ),
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
STATE: dict[str, Any] = {"verbose": False}

Out = Annotated[Path, typer.Option("--out", "-o", help="Study folder to write into.")]
#: more worker processes than this is a typo, not a machine (each holds ~300 MB)
MAX_WORKERS = 512


def finite_range(low: float | None = None, high: float | None = None, *, above: bool = False):
    """A typer callback: the value (if given) must be finite, ≥ ``low`` (> ``low`` when
    ``above``) and ≤ ``high``; click's FloatRange lets NaN through."""

    def check(value: float | None) -> float | None:
        if value is None:
            return value
        too_low = low is not None and (value <= low if above else value < low)
        if not math.isfinite(value) or too_low or (high is not None and value > high):
            lo = "" if low is None else f"{'>' if above else '≥'} {low:g}"
            hi = "" if high is None else f"≤ {high:g}"
            raise typer.BadParameter(f"{value!r} is not a finite number {lo} {hi}".strip())
        return value

    return check


def _version(value: bool) -> None:
    if value:
        console.print(f"popnavshift {__version__}")
        raise typer.Exit()


@app.callback()
def main_callback(
    verbose: Annotated[
        bool, typer.Option("--verbose", "-v", help="Show details and tracebacks.")
    ] = False,
    version: Annotated[
        bool,
        typer.Option(
            "--version", callback=_version, is_eager=True, help="Print the version and exit."
        ),
    ] = False,
) -> None:
    STATE["verbose"] = verbose
    configure_logging(verbose)


def configure_logging(verbose: bool) -> None:
    """Show the package's log on the console: warnings, and with ``-v`` retries and
    re-asks too; every line is redacted."""
    from rich.logging import RichHandler

    logger = logging.getLogger("popnavshift")
    for old in [h for h in logger.handlers if getattr(h, "popnavshift_cli", False)]:
        logger.removeHandler(old)
    handler = RichHandler(console=console, markup=False, show_path=False, show_time=verbose)
    handler.popnavshift_cli = True  # type: ignore[attr-defined]
    handler.addFilter(RedactingFilter())
    logger.addHandler(handler)
    logger.setLevel(logging.INFO if verbose else logging.WARNING)


def folder(path: Path) -> Path:
    """Create the study folder ``path``; ConfigError if it is a file or not writable."""
    if path.exists() and not path.is_dir():
        raise ConfigError(f"--out {path} exists and is not a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".popnavshift-write-test-{os.getpid()}"
        probe.touch()
        probe.unlink()
    except OSError as exc:
        raise ConfigError(
            f"--out {path} is not a writable folder ({exc.strerror or exc})",
            hint="choose another --out or fix its permissions",
        ) from None
    return path


def check_workers(workers: int, executor: str = "local") -> None:
    """Local worker processes beyond 4 per CPU only thrash memory (each holds ~300 MB)."""
    cpus = os.cpu_count() or 1
    if executor == "local" and workers > 4 * cpus:
        raise ConfigError(f"--workers {workers} is more than 4 per CPU ({cpus} CPUs here)",
                          hint=f"use at most {4 * cpus}, or --executor ray for a cluster")


def say(text: object) -> str:
    """``text`` (a path, a name, a server's message) made safe for rich markup."""
    return escape(redact(str(text)))


from . import data, evaluate, population, simulation, study  # noqa: E402, F401  (register the commands)

INTERRUPTED = "[yellow]interrupted[/]: finished work is kept; run the same command to resume"


def main() -> None:
    """Entry point: run the app, turning user and usage errors into one line, exit 2."""
    try:
        result = app(standalone_mode=False, prog_name="popnavshift")
    except PopNavShiftError as exc:
        if STATE["verbose"]:
            console.print_exception()
        fail(str(exc))
    except _INTERRUPTS:
        result = 130
    except _USAGE_ERRORS as exc:
        _usage_error(exc)
    except typer.Exit as exc:
        sys.exit(exc.exit_code)
    if result == 130:  # typer returns 130 when Ctrl-C interrupted a command
        console.print(INTERRUPTED)
        sys.exit(130)


def fail(message: str) -> NoReturn:
    """Print one red ``error:`` line (escaped, redacted) and exit with code 2."""
    one_line = " ".join(message.split())
    console.print(f"[bold red]error:[/] {say(one_line)}", highlight=False, soft_wrap=True)
    sys.exit(2)


def _usage_errors() -> tuple[tuple[type[BaseException], ...], tuple[type[BaseException], ...]]:
    """(usage errors, aborts) of the installed typer: recent typer vendors its own click
    (``typer._click``, whose exceptions derive from ``typer.TyperException``), older
    ones raise click's; catch both so a usage error is never a traceback."""
    usage: list[type[BaseException]] = [typer.TyperException]
    aborts: list[type[BaseException]] = [typer.Abort]
    try:
        import click

        usage.append(click.exceptions.ClickException)
        aborts.append(click.exceptions.Abort)
    except ImportError:  # pragma: no cover - typer without click
        pass
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
