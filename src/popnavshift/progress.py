"""Rich progress bars and the console shared by the CLI and the pipeline layer.

On a terminal, a live bar; when stderr is not one (a log file, CI, ``nohup``), a live bar
would print nothing until the end, so a plain line is printed every
:data:`PLAIN_EVERY` s instead (:class:`PlainLines`), e.g.
``probing (openai): 120/400 records, 4 in flight, 131 calls, 3 retries, 0 failed``.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from rich.console import Console
from rich.markup import escape

# rich.progress is imported by the bars themselves: the command line imports this module
# before any command, and a bar is only drawn by a command that runs
console = Console(stderr=True)
#: seconds between two plain progress lines (stderr not a terminal)
PLAIN_EVERY = 10.0


class PlainLines:
    """Prints ``{what}: {done}/{total} {unit}{, note()}`` every ``every`` s from a daemon
    thread (so a stalled run, a server retrying, still shows its counts), and once more at
    the end when it printed any."""

    def __init__(self, what: str, total: int, unit: str, note: Callable[[], str] | None,
                 every: float) -> None:
        self.what, self.total, self.unit, self.note, self.every = what, total, unit, note, every
        self.done = 0
        self.printed = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)

    def advance(self, n: int = 1) -> None:
        self.done += n

    def line(self) -> str:
        extra = self.note() if self.note is not None else ""
        return f"{self.what}: {self.done}/{self.total} {self.unit}" + (f", {extra}" if extra
                                                                      else "")

    def _loop(self) -> None:
        while not self._stop.wait(self.every):
            console.print(self.line(), markup=False, highlight=False)
            self.printed += 1

    def __enter__(self) -> PlainLines:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        if self.printed:  # a run short enough to print no line stays silent
            console.print(self.line(), markup=False, highlight=False)


@contextmanager
def progress_bar(description: str, total: int, enabled: bool = True, *,
                 note: Callable[[], str] | None = None, unit: str = "records",
                 every: float = PLAIN_EVERY) -> Iterator:
    """Yield ``advance(n)``; shows a bar (done/total, elapsed, ETA) on the console, or,
    when stderr is not a terminal, a plain line every ``every`` s with ``note()`` (e.g.
    calls, retries and failures so far)."""
    if not enabled or total <= 0:
        yield lambda n=1: None
        return
    if not console.is_terminal:
        with PlainLines(description, total, unit, note, every) as lines:
            yield lines.advance
        return
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    with Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console,
        transient=True,
    ) as bar:
        task = bar.add_task(escape(description), total=total)
        yield lambda n=1: bar.advance(task, n)


@contextmanager
def run_progress(total: int, enabled: bool = True) -> Iterator:
    """Progress for simulation runs: done/total, runs/s, elapsed, ETA."""
    if not enabled or total <= 0:
        yield lambda n=1: None
        return
    if not console.is_terminal:
        with PlainLines("runs", total, "runs", None, PLAIN_EVERY) as lines:
            yield lines.advance
        return
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TaskProgressColumn,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    with Progress(
        TextColumn("[bold]runs"),
        BarColumn(),
        MofNCompleteColumn(),
        TaskProgressColumn(),
        TextColumn("{task.fields[rate]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console,
    ) as bar:
        start = time.perf_counter()
        task = bar.add_task("runs", total=total, rate="")
        done = 0

        def advance(n: int = 1) -> None:
            nonlocal done
            done += n
            rate = done / max(time.perf_counter() - start, 1e-9)
            bar.update(task, advance=n, rate=f"{rate:.1f} runs/s")

        yield advance
