"""The ``popnavshift`` command line: one dispatcher, one subcommand per stage.

User errors (:class:`PopNavShiftError`) become one red line and exit code 2;
``--verbose`` adds the traceback. Everything else is a bug and shows a traceback.
Commands live in :mod:`.population` (personas → populations), :mod:`.simulation`
(episodes, simulate, replay, bench) and :mod:`.study` (plan, run, report).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from .. import __version__
from ..errors import ConfigError, PopNavShiftError
from ..progress import console

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


def folder(path: Path) -> Path:
    """Create the study folder ``path`` (error if it is a file)."""
    if path.exists() and not path.is_dir():
        raise ConfigError(f"--out {path} exists and is not a folder")
    path.mkdir(parents=True, exist_ok=True)
    return path


from . import data, evaluate, population, simulation, study  # noqa: E402, F401  (register the commands)

INTERRUPTED = "[yellow]interrupted[/]: finished work is kept; run the same command to resume"


def main() -> None:
    """Entry point: run the app, turning user errors into one line and exit code 2."""
    import click

    try:
        result = app(standalone_mode=False)
    except PopNavShiftError as exc:
        if STATE["verbose"]:
            console.print_exception()
        console.print(f"[bold red]error:[/] {exc}", highlight=False, soft_wrap=True)
        sys.exit(2)
    except (KeyboardInterrupt, click.exceptions.Abort):
        result = 130
    except click.exceptions.ClickException as exc:  # usage errors (bad option, missing arg)
        exc.show()
        sys.exit(2)
    except typer.Exit as exc:
        sys.exit(exc.exit_code)
    if result == 130:  # typer returns 130 when Ctrl-C interrupted a command
        console.print(INTERRUPTED)
        sys.exit(130)
