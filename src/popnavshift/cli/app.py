"""The ``popnavshift`` app and what every command module shares: the typer app and
its global options, the ``--out`` option, folder and worker checks, and :func:`say`
(markup-safe, redacted text). Command modules import from here; :mod:`popnavshift.cli`
registers them and runs the app."""

from __future__ import annotations

import inspect
import logging
import math
import os
import textwrap
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.markup import escape

from ..errors import ConfigError
from ..progress import console
from ..redact import RedactingFilter, redact
from ..version import __version__

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
#: stdout, for a command whose text is its output (a table of counts, a prompt): the
#: console of progress and messages writes to stderr
stdout = Console(soft_wrap=True, highlight=False)

Out = Annotated[Path, typer.Option("--out", "-o", help="Study folder to write into.")]
StudyArg = Annotated[
    str | None,
    typer.Argument(help="A built-in study (paper; paper-large, paper-nulls, paper-xl and "
                        "paper-xl-nulls, which decide more of its headline; quick; pilot) or a "
                        "study YAML file. Default: paper."),
]
Replicates = Annotated[int | None, typer.Option(
    "--replicates", min=1, max=999,
    help="Extend the study to this many replicates of every null design (more placebos for "
    "calibration, a sharper null), without re-running it: only the new runs are simulated.")]
SeedSets = Annotated[int | None, typer.Option(
    "--seed-sets", min=1, max=100,
    help="Extend every part that repeats its episodes on extra seed sets (the matched pair, "
    "its swap null, the noise floor) to this many seed sets, the study seed's included: a "
    "tighter null for the verdicts; only the new runs are simulated.")]


def extended(study, replicates: int | None, seed_sets: int | None):
    """``study`` extended by ``--replicates`` and ``--seed-sets`` (as it is without them)."""
    if replicates is None and seed_sets is None:
        return study
    return study.extended(replicates=replicates, seed_sets=seed_sets)


#: more worker processes than this is a typo, not a machine (each holds ~300 MB)
MAX_WORKERS = 512
#: columns a table of several text columns needs to stay readable; a narrower terminal
#: gets one block per row instead (``plan``'s power advice, ``describe``)
WIDE = 120


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
    handler.addFilter(TerminalFilter())
    logger.addHandler(handler)
    logger.setLevel(logging.INFO if verbose else logging.WARNING)


class TerminalFilter(RedactingFilter):
    """Redacts each record's message and writes its control characters as their codes: a
    server's error text, logged under ``-v``, must not drive the terminal either."""

    def filter(self, record: logging.LogRecord) -> bool:
        super().filter(record)
        record.msg = printable(str(record.msg))
        return True


def print_traceback() -> None:
    """The current exception's traceback (``-v``), every line escaped and redacted: its
    message may be a server's text (an OSC or a screen clear in an error body)."""
    import traceback

    text = redact("".join(traceback.format_exc()))
    console.print(printable(text, lines=True), markup=False, highlight=False,
                  soft_wrap=True)


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


def default_folder(study_name: str) -> Path:
    """A study's default folder: ``./study`` for the paper study (the one `make run`,
    `evaluate`, `calibrate` and `show-prompt` read by default), ``./study-<name>`` else."""
    return Path("study" if study_name == "paper" else f"study-{study_name}")


def check_workers(workers: int, executor: str = "local") -> None:
    """The executor exists and its optional package is installed (checked before any stage
    runs); local worker processes beyond 4 per CPU only thrash memory (each holds ~300 MB)."""
    from ..engine.executors import check_executor  # the engine loads navground: lazily

    check_executor(executor)
    cpus = os.cpu_count() or 1
    if executor == "local" and workers > 4 * cpus:
        raise ConfigError(f"--workers {workers} is more than 4 per CPU ({cpus} CPUs here)",
                          hint=f"use at most {4 * cpus}, or --executor ray for a cluster")


def say(text: object, lines: bool = False) -> str:
    """``text`` (a path, a name, a server's message) made safe for the terminal: control
    characters shown as escapes, rich markup escaped, secrets redacted. ``lines`` keeps
    the line breaks of a text of several lines (a table the code formatted itself)."""
    return escape(redact(printable(str(text), lines)))


def prose(text: str, console: Console = stdout) -> None:
    """Print ``text`` (markup, data already passed through :func:`say`) wrapped at the
    terminal's width, between words (a word longer than a line, a deep path, is folded):
    the consoles keep a line whole by default, so that an id in a table is never cut,
    which leaves a sentence as wide as it is long."""
    console.print(text, soft_wrap=False, highlight=False)


def indented(text: str, console: Console = stdout, indent: int = 4) -> None:
    """Print plain ``text`` (no markup; made printable and redacted, as :func:`say` does)
    wrapped at the terminal's width and indented by ``indent`` spaces, a word never cut (an
    id or a path longer than a line stays whole)."""
    pad = " " * indent
    wrapped = textwrap.fill(redact(printable(text)), width=max(console.width, indent + 20),
                            initial_indent=pad, subsequent_indent=pad,
                            break_long_words=False, break_on_hyphens=False)
    console.print(wrapped, markup=False, highlight=False, soft_wrap=True)


def check_controllers(*specs: str) -> None:
    """Each of ``specs`` (a controller id, ``none`` for no robot) names a registered
    controller, a navground behaviour or an entry point, or is a ``package.module:Class``
    (checked when made), else UnknownNameError with a did-you-mean, case aside. Imports
    only the registry and navground's core: a misspelt name fails at once."""
    from ..sim.controllers import CONTROLLERS

    for spec in specs:
        if spec != "none":
            CONTROLLERS.check_name(spec)


def reflow(doc: str) -> str:
    """A command's docstring as its ``--help`` should show it: each paragraph (the text
    between blank lines) on one line, for the terminal to wrap at its width; a paragraph
    that opens with ``\\b`` keeps its lines, each indented line joined to the one above
    (an item of a list)."""
    out = []
    for para in inspect.cleandoc(doc).split("\n\n"):
        if not para.startswith("\b"):
            out.append(" ".join(line.strip() for line in para.splitlines()))
            continue
        items: list[str] = []
        for line in para.removeprefix("\b").strip("\n").splitlines():
            if line[:1].isspace() and items:
                items[-1] += " " + line.strip()
            else:
                items.append(line.strip())
        out.append("\n".join(items))
    return "\n\n".join(out)


def reflow_help(typer_app: typer.Typer) -> None:
    """Reflow the help of every command of ``typer_app`` (:func:`reflow`): typer's rich help
    keeps a docstring's line breaks, which a terminal narrower or wider than the source
    shows mid-sentence."""
    for info in typer_app.registered_commands:
        doc = info.help or inspect.getdoc(info.callback) or ""
        info.help = reflow(doc)


def printable(text: str, lines: bool = False) -> str:
    """``text`` with every character that is not printable (ESC of an escape sequence,
    NUL, a newline, a bidi override, a zero-width mark…) written as its code (``\\x1b``,
    ``\\u202e``): data from a persona file or a server must never drive the terminal,
    forge a line or hide what it shows. ``lines`` keeps the newlines of a multi-line
    text (a prompt)."""
    if text.isprintable():
        return text
    if lines:
        return "\n".join(printable(line) for line in text.split("\n"))
    return "".join(ch if ch.isprintable() else _code(ord(ch)) for ch in text)


def _code(point: int) -> str:
    return f"\\x{point:02x}" if point < 0x100 else f"\\u{point:04x}"
