"""Commands that explain a study folder: show-prompt (what a respondent was asked)."""

from __future__ import annotations

import difflib
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from ..errors import InputError
from .app import WIDE, app, indented, printable, say, stdout

if TYPE_CHECKING:  # the tables are read by the command, not by --help
    import pandas as pd

StudyOpt = Annotated[Path, typer.Option("--study", "-s", help="Study folder.")]
out = stdout


@app.command("show-prompt")
def show_prompt(
    persona_id: Annotated[str, typer.Argument(help="A persona_id of the study.")],
    study: StudyOpt = Path("study"),
    variant: Annotated[
        str | None,
        typer.Option(help="baseline or deadline; default: every variant the persona was asked."),
    ] = None,
) -> None:
    """Print the exact system and user messages a respondent got for one persona.

    Example: popnavshift show-prompt syn-000042 --study study

    The text is rebuilt from personas.parquet with the respondent's own prompt
    builder, and the answer recorded in responses.parquet follows it. The rule
    respondent reads the fields instead of this text; re-asks after an invalid
    answer (model reply + correction) are not shown.
    """
    from ..pipeline import read_table
    from ..responses.prompt import respondent_messages

    personas = read_table(study / "personas.parquet", "personas")
    record = _persona(personas, persona_id, study / "personas.parquet")
    asked = _asked(study, persona_id)
    variants = [variant] if variant else (sorted(asked) or ["baseline"])
    for v in variants:
        system, user = respondent_messages(record, v)
        who = asked.get(v, "not asked in this study")
        out.print(f"[bold]persona {say(persona_id)} · variant {say(v)}[/] · {say(who)}")
        out.print("[dim]── system ──[/]")
        out.print(printable(system, lines=True), markup=False)
        out.print("[dim]── user ──[/]")
        out.print(printable(user, lines=True), markup=False)
        answer = _answer(study, persona_id, v)
        if answer:
            out.print("[dim]── recorded answer ──[/]")
            out.print(printable(answer, lines=True), markup=False)


def _answer(study: Path, persona_id: str, variant: str) -> str:
    """The answer recorded for (persona, variant): the 8 actions and the 7 self-ratings."""
    path = study / "responses.parquet"
    if not path.exists():
        return ""
    from ..pipeline import read_table  # a damaged table is one line
    from ..responses.schema import LEVELS
    from ..tables import ACTION_COLUMNS, Q_COLUMNS

    rows = read_table(path, "responses")
    row = rows[(rows["persona_id"] == persona_id) & (rows["variant"] == variant)]
    if row.empty:
        return ""
    r = row.iloc[0]
    actions = ", ".join(f"P{c[7:]}: {r[c]}" for c in ACTION_COLUMNS)
    levels = dict(zip((0.0, 0.25, 0.5, 0.75, 1.0), LEVELS, strict=True))
    items = ", ".join(f"{c[2:]}: {levels.get(float(r[c]), r[c])}" for c in Q_COLUMNS)
    return f"actions  {actions}\nratings  {items}"


def _persona(personas: pd.DataFrame, persona_id: str, where: Path) -> dict:
    match = personas[personas["persona_id"].astype(str) == persona_id]
    if match.empty:
        ids = personas["persona_id"].astype(str)
        close = difflib.get_close_matches(persona_id, ids, n=3)
        digits = "".join(ch for ch in persona_id if ch.isdigit())
        if digits:  # syn-42 for syn-000042: the same number, other zero padding, first
            same = [i for i in ids if "".join(ch for ch in i if ch.isdigit()).lstrip("0")
                    == digits.lstrip("0")][:3]
            close = same + [c for c in close if c not in same]
        raise InputError(
            f"{where}: no persona {persona_id!r}",
            hint=f"did you mean {', '.join(map(repr, close))}?" if close else None,
        )
    return match.iloc[0].to_dict()


def _asked(study: Path, persona_id: str) -> dict[str, str]:
    """Variant → "respondent (model)" (or "invalid answer") per variant asked of the persona."""
    from ..pipeline import read_table

    asked: dict[str, str] = {}
    path = study / "responses.parquet"
    if path.exists():
        rows = read_table(path, "responses")
        for r in rows[rows["persona_id"] == persona_id].itertuples():
            asked[str(r.variant)] = f"respondent {r.respondent} ({r.model})"
    invalid = study / "responses_invalid.parquet"
    if invalid.exists():
        rows = read_table(invalid, "responses_invalid")
        for r in rows[rows["persona_id"] == persona_id].itertuples():
            asked[str(r.variant)] = f"invalid answer: {r.error}"
    return asked


@app.command()
def describe(
    study: Annotated[
        Path | None, typer.Argument(help="Study folder; omitted: every table, as Markdown.")
    ] = None,
    table: Annotated[str | None, typer.Argument(help="One table, e.g. runs.")] = None,
    markdown: Annotated[
        bool, typer.Option("--markdown", help="Print Markdown (the text of docs/data.md).")
    ] = False,
) -> None:
    """Print the data dictionary: every column's dtype, unit, key role, NaN meaning.

    Example: popnavshift describe study runs

    With a study folder, only the tables it holds, with their row counts, and
    columns the folder has but the dictionary does not declare are flagged.
    """
    from ..dictionary import STUDY_TABLES, data_markdown, table_markdown
    from ..errors import UnknownNameError
    from ..tables import SPECS

    names = list(STUDY_TABLES)
    if table is None and study is not None and not study.exists() and (
            str(study).removesuffix(".parquet") in STUDY_TABLES):
        study, table = None, str(study)  # `describe runs`: the table, not a folder
    if table is not None:
        name = table.removesuffix(".parquet")
        if name not in STUDY_TABLES:
            raise UnknownNameError("table", name, STUDY_TABLES)
        names = [name]
    if study is not None:
        if not study.is_dir():
            raise InputError(f"{study}: no such study folder",
                             hint="give a study folder, then optionally a table: "
                             "popnavshift describe STUDY runs")
        names = [n for n in names if (study / SPECS[n].file).exists()]
        if not names:
            raise InputError(f"{study}: holds none of the table(s) {table or 'of a study'}")
    if markdown:
        text = data_markdown() if study is None and table is None else "\n".join(
            table_markdown(SPECS[n]) for n in names
        )
        typer.echo(text, nl=False)
        return
    for name in names:
        _print_table(SPECS[name], study)


def _print_table(spec, study: Path | None) -> None:
    from rich.table import Table
    from rich.text import Text

    from ..dictionary import role
    from ..tables import DTYPES

    title = spec.file
    present: list[str] | None = None
    if study is not None:
        import pyarrow.parquet as pq

        try:
            meta = pq.ParquetFile(study / spec.file)
        except (OSError, ValueError) as exc:  # pyarrow's ArrowInvalid is a ValueError
            raise InputError(f"{study / spec.file} is damaged (not a readable Parquet file: "
                             f"{exc})", hint="`popnavshift run` on the folder makes it again"
                             ) from None
        present = [printable(n) for n in meta.schema_arrow.names]
        title = f"{study / spec.file} · {meta.metadata.num_rows} rows"
    undeclared = [n for n in present or [] if n not in spec.names]
    if out.width < WIDE:  # a narrow terminal: one short block per column, not a 7-column grid
        out.print(Text(title, style="bold"))  # a path: whole
        out.print(Text(f"one row per {spec.doc[4:]}"), soft_wrap=False)  # wrapped
        for c in spec.columns:
            head = " · ".join(x for x in (c.name, DTYPES[c.kind], c.unit, role(spec, c),
                                          f"→ {c.refers}" if c.refers else "") if x)
            out.print(Text(head, style="bold"), soft_wrap=False)
            indented(c.doc + (f" (missing: {c.missing})" if c.missing else ""), out)
        for extra in undeclared:
            out.print(Text(f"{extra} · not declared", style="bold red"), soft_wrap=False)
        return
    grid = Table(title=Text(title), caption=Text(f"one row per {spec.doc[4:]}"))
    for head in ("column", "dtype", "unit", "key", "refers to", "missing means", "meaning"):
        grid.add_column(head, overflow="fold", ratio=3 if head == "meaning" else 1)
    for c in spec.columns:
        cells = (c.name, DTYPES[c.kind], c.unit, role(spec, c), c.refers, c.missing, c.doc)
        grid.add_row(*(Text(x) for x in cells))
    for extra in undeclared:
        grid.add_row(Text(extra), *(Text("") for _ in range(5)), Text("not declared"))
    out.print(grid)
