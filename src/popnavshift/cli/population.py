"""Population pipeline commands: personas, probe, profiles, populations."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.table import Table

from ..errors import ConfigError
from ..progress import console
from .app import Out, app, finite_range, folder, say


def _settings(personas: dict[str, Any] | None = None, respondent: dict[str, Any] | None = None,
              respondent2: str | None = None, **kw: Any):
    """The pipeline settings of a stage command: its persona-source and respondent options
    validated by the study file's own models (a value a study refuses is refused here,
    naming the option), the rest as given (``None``: the default)."""
    from pydantic import ValidationError

    from ..design.specs import PersonaSource, RespondentSpec
    from ..pipeline import PopulationSettings

    def model(cls, given: dict[str, Any]):
        try:
            return cls(**{k: v for k, v in given.items() if v is not None})
        except ValidationError as e:
            err = e.errors()[0]
            where = ".".join(str(x) for x in err["loc"])
            got = err.get("input")
            raise ConfigError(f"--{where.replace('_', '-')}: {err['msg']}; got {got!r}") from None

    if personas is not None:
        kw["personas"] = model(PersonaSource, personas)
    if respondent is not None:
        kw["respondent"] = model(RespondentSpec, respondent)
    if respondent2 is not None:  # only its profile-set label is read after the probes
        kw["respondent2"] = RespondentSpec(name=respondent2)
    return PopulationSettings(**{k: v for k, v in kw.items() if v is not None})


def _respondent_options(api_key_env: str | None, **given: Any) -> dict[str, Any]:
    """The respondent options the user gave (``None`` = not given: the respondent's
    default); ``--api-key-env none`` means a local server that needs no key."""
    opts = {k: v for k, v in given.items() if v is not None}
    if api_key_env is not None:
        opts["api_key_env"] = None if api_key_env.strip().lower() in ("", "none") else api_key_env
    return opts


#: a respondent option's command-line flag where its name differs from the option's
_FLAG = {"max_concurrency": "--concurrency", "max_consecutive_failures": "--max-failures",
         "seed": "--respondent-seed"}


def json_option(name: str, text: str | None) -> Any:
    """The JSON value of option ``name`` (None when not given); ConfigError naming it."""
    if text is None:
        return None
    try:
        return json.loads(text)
    except ValueError as exc:
        raise ConfigError(f"{name}: not JSON ({exc})",
                          hint=f"""e.g. {name} '{{"cache_prompt": false}}'""") from None


def _opt(help_: str, **kw: Any) -> Any:
    return typer.Option(help=help_, rich_help_panel="LLM respondents", **kw)


@app.command()
def personas(
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            "-o",
            help="Study folder, or the Parquet file to "
            "write (its folder gets the provenance JSON).",
        ),
    ] = Path("study"),
    source: Annotated[
        str,
        typer.Option(
            help="'synthetic', a CSV/JSONL/Parquet file, a MatrAIx Persona 1M release folder, "
            "or hf://MatrAIx2026/MatrAIx_Persona_1M_Public_Release (needs the 'hf' extra)."
        ),
    ] = "synthetic",
    n: Annotated[int, typer.Option(min=1, help="Number of personas to sample.")] = 600,
    seed: Annotated[int, typer.Option(min=0, help="Sampling / generation seed.")] = 0,
    missing: Annotated[
        str,
        typer.Option(
            help="Records missing required fields: require "
            "(skip and count), fill (schema default), error."
        ),
    ] = "require",
    codebook: Annotated[
        Path | None,
        typer.Option(help="Release only: codebook JSON of a folder not laid out as published."),
    ] = None,
    only_source: Annotated[
        list[str] | None,
        typer.Option(help="Release only: keep records of this source (gss, wiki...); repeat."),
    ] = None,
    verify_checksums: Annotated[
        bool, typer.Option(help="Release only: check shards against manifest.json.")
    ] = True,
) -> None:
    """Write personas.parquet: persona records from a generator, a table or a release.

    Example: popnavshift personas --source synthetic --n 600 --seed 0 --out study

    From a release, minors (by age_bracket) are never sampled; personas.json records
    what each step dropped and the source mix.
    """
    from ..engine.lock import study_lock
    from ..engine.runner import run_stage
    from ..pipeline import run_personas

    target = out if out.suffix == ".parquet" else out / "personas.parquet"
    study_folder = folder(target.parent)
    settings = _settings(
        personas=dict(
            source=source,
            n=n,
            missing=missing,
            codebook=None if codebook is None else str(codebook),
            sources=tuple(only_source) if only_source else None,
            verify_checksums=verify_checksums,
        ),
        seed=seed,
    )
    with study_lock(study_folder):
        if target == study_folder / "personas.parquet":  # the study's table: stamped
            df = run_stage(study_folder, "personas", settings)
        else:
            df = run_personas(study_folder, settings, target)
    mix = ", ".join(f"{k} {v}" for k, v in df["source"].value_counts().sort_index().items())
    console.print(f"[green]{len(df)} personas[/] ({say(mix)}) → {say(target)}")


@app.command()
def probe(
    out: Out = Path("study"),
    respondent: Annotated[
        str, typer.Option(help="rule (offline default), openai, gemini, or a plug-in name.")
    ] = "rule",
    model: Annotated[str | None, typer.Option(help="LLM model name.")] = None,
    base_url: Annotated[
        str | None,
        typer.Option(
            help="OpenAI-compatible server URL, e.g. http://127.0.0.1:11434/v1 for Ollama."
        ),
    ] = None,
    api_key_env: Annotated[
        str | None,
        typer.Option(
            help="Environment variable holding the API key (never pass a key itself); "
            "'none' for local servers such as Ollama."
        ),
    ] = None,
    temperature: Annotated[
        float | None, _opt("Sampling temperature (0–2).", callback=finite_range(0, 2))
    ] = None,
    respondent_seed: Annotated[
        int | None, typer.Option(min=0, help="Respondent seed (LLM seed or rule noise).")
    ] = None,
    samples: Annotated[
        int, typer.Option(min=1, max=100, help="Independent samples per persona, each sent "
                          "with its own seed (the audit's test–retest needs 2 or more; the "
                          "rule respondent gives identical samples).")
    ] = 1,
    concurrency: Annotated[int | None, _opt("Concurrent LLM requests.", min=1, max=256)] = None,
    rate_limit: Annotated[
        float | None, _opt("LLM requests per second.", callback=finite_range(0, above=True))
    ] = None,
    timeout: Annotated[
        float | None, _opt("Seconds to wait for one reply.", callback=finite_range(0, above=True))
    ] = None,
    max_retries: Annotated[
        int | None, _opt("Transport retries per request (HTTP 429/5xx, timeouts).", min=0, max=20)
    ] = None,
    max_reasks: Annotated[
        int | None, _opt("Re-asks per record after an invalid reply.", min=0, max=10)
    ] = None,
    max_tokens: Annotated[
        int | None, _opt("Most tokens a reply may have (sent to the server).", min=1)
    ] = None,
    ready_timeout: Annotated[
        float | None,
        _opt("Seconds to wait for a server that is starting or loading its model.",
             callback=finite_range(0)),
    ] = None,
    max_failures: Annotated[
        int | None,
        _opt("Stop after this many records in a row fail at the transport level.", min=1),
    ] = None,
    max_retry_after: Annotated[
        float | None,
        _opt("Longest Retry-After a rate-limiting server gets (s; default 60).",
             callback=finite_range(0)),
    ] = None,
    deadline: Annotated[
        float | None,
        _opt("Most seconds the whole probe stage may take: the model check, every call "
             "and wait, calls in flight; what was answered is cached.",
             callback=finite_range(0, above=True)),
    ] = None,
    extra_body: Annotated[
        str | None,
        _opt("JSON object of server-specific request fields, e.g. '{\"cache_prompt\": "
             "false}' for reproducible llama.cpp answers (docs/llm.md).")
    ] = None,
    model_sha256: Annotated[
        str | None,
        _opt("sha256 of the served model file, when you know it: part of the model's "
             "identity in the cache and the records.")
    ] = None,
    fingerprint: Annotated[
        bool | None,
        _opt("Ask the fixed canary prompts first, so a different model behind the same name "
             "is detected (default on).")
    ] = None,
    matched_n: Annotated[
        int, typer.Option(min=1, help="Matched sample size (deadline re-ask).")
    ] = 202,
    seed: Annotated[int, typer.Option(min=0, help="Seed of the matched sample.")] = 0,
) -> None:
    """Ask every persona the 8 encounter probes; write responses.parquet.

    Reads OUT/personas.parquet. Also asks the matched sample again with time
    pressure set to Deadline. Network respondents cache in OUT/cache/llm.sqlite,
    so a second run makes no calls. Invalid records are listed, never dropped.
    """
    from ..engine.lock import study_lock
    from ..engine.runner import run_stage

    out = folder(out)
    opts = _respondent_options(
        api_key_env, model=model, base_url=base_url, temperature=temperature,
        seed=respondent_seed, max_concurrency=concurrency, rate_limit=rate_limit,
        timeout=timeout, max_retries=max_retries, max_reasks=max_reasks, max_tokens=max_tokens,
        ready_timeout=ready_timeout, max_consecutive_failures=max_failures,
        max_retry_after=max_retry_after, deadline=deadline,
        extra_body=json_option("--extra-body", extra_body), model_sha256=model_sha256,
        fingerprint=fingerprint,
    )
    if respondent == "rule":
        llm_only = sorted(k for k in opts if k != "seed")
        if llm_only:  # given on purpose, and ignored: say so rather than drop them
            raise ConfigError(
                "--respondent rule takes no LLM option; given: "
                + ", ".join(_FLAG.get(k, "--" + k.replace("_", "-")) for k in llm_only),
                hint="they apply to --respondent openai or gemini; the rule respondent "
                "takes --respondent-seed")
    s = _settings(respondent=dict(name=respondent, options=opts, samples=samples),
                  matched_n=matched_n, seed=seed)
    started = time.perf_counter()
    with study_lock(out):
        df = run_stage(out, "responses", s, stamp=_seed_agrees(out, seed))
    stats = json.loads((out / "responses.json").read_text())
    console.print(
        f"[green]{len(df)} valid responses[/]"
        + (f" ({samples} samples per persona and variant)" if samples > 1 else "")
        + f" ({stats['invalid']} invalid, "
        f"{stats['calls']} calls, {stats['cached']} cache hits) in "
        f"{time.perf_counter() - started:.1f} s → {say(out / 'responses.parquet')}"
    )
    if stats["invalid"]:
        import pandas as pd

        bad = pd.read_parquet(out / "responses_invalid.parquet")
        table = Table("persona", "variant", "error", title="invalid records")
        for r in bad.head(20).itertuples():
            table.add_row(say(r.persona_id), say(r.variant), say(r.error))
        console.print(table)


@app.command()
def profiles(
    out: Out = Path("study"),
    mapping: Annotated[
        list[str] | None, typer.Option(help="Mapping(s) A–D; repeat the option. Default: all four.")
    ] = None,
) -> None:
    """Map responses to the 7 motion parameters; write profiles.parquet."""
    from ..engine.lock import study_lock
    from ..engine.runner import run_stage

    out = folder(out)
    maps = tuple(mapping) if mapping else ("A", "B", "C", "D")
    with study_lock(out):
        settings = _settings(mappings=maps, respondent2=_second_respondent(out))
        df = run_stage(out, "profiles", settings)
    console.print(
        f"[green]{len(df)} profiles[/] (mappings {say(', '.join(maps))}) → "
        f"{say(out / 'profiles.parquet')}"
    )


@app.command()
def populations(
    out: Out = Path("study"),
    matched_n: Annotated[int, typer.Option(min=1, help="Matched sample size.")] = 202,
    seed: Annotated[int, typer.Option(min=0, help="Seed of the matched sample.")] = 0,
) -> None:
    """Build the 8 population conditions; write populations.parquet and profile figures."""
    from ..engine.lock import study_lock
    from ..engine.runner import run_stage

    out = folder(out)
    sets = _profile_sets_in(out / "profiles.parquet")
    with study_lock(out):
        table = run_stage(out, "populations", _settings(matched_n=matched_n, seed=seed, **sets),
                          stamp=_seed_agrees(out, seed))
    print_sizes(table)
    console.print(f"→ {say(out / 'populations.parquet')}, figures in {say(out / 'figures')}")


def _profile_sets_in(path: Path) -> dict[str, Any]:
    """The settings of the profile sets in ``path`` that the populations stage reads: the
    structure sets and a second respondent's set are built as ``run`` builds them (the
    profiles' stamp covers them, the populations' does not)."""
    from ..pipeline import read_table
    from ..populations.perturb import ProfileSet

    found = sorted(set(read_table(path, "profiles")["mapping"]))
    if "A" not in found:
        raise ConfigError(f"{path} has no Mapping A profiles (membership is defined by Mapping A)")
    sets = [ProfileSet.parse(m) for m in found]
    second = [p.arg for p in sets if p.perturbation == "second_respondent"]
    return {"mappings": tuple(p.label for p in sets if p.perturbation == "none"),
            "structure": any(p.is_structure for p in sets),
            "respondent2": second[0] if second else None}


def _second_respondent(out: Path) -> str | None:
    """The second respondent whose answers the folder holds (``responses.json``), whose
    profile set ``run`` builds beside the mappings: the responses' stamp covers it, the
    profiles' does not."""
    from ..populations.perturb import ProfileSet

    try:
        second = json.loads((out / "responses.json").read_text("utf-8")).get("second")
    except (OSError, ValueError, AttributeError):
        return None
    return ProfileSet.parse(second["label"]).arg if isinstance(second, dict) else None


def _seed_agrees(out: Path, seed: int) -> bool:
    """Whether the folder's personas were drawn with ``seed``. ``run`` uses one seed for
    the personas, the matched sample and the nulls, and only the personas' stamp covers
    it: a later stage run with another seed gets no stamp (``run`` redoes it)."""
    try:
        return json.loads((out / "personas.json").read_text("utf-8")).get("seed") == seed
    except (OSError, ValueError, AttributeError):
        return False


def print_sizes(table) -> None:
    from ..populations.build import population_sizes

    sizes = population_sizes(table[table["mapping"] == "A"])
    t = Table("population", "n", title="population sizes")
    for name, size in sizes.items():
        t.add_row(say(name), str(size))
    console.print(t)
