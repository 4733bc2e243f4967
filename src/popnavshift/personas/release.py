"""The files of a MatrAIx Persona 1M release folder, as published, and how to get them.

Layout of the public release (``MatrAIx2026/MatrAIx_Persona_1M_Public_Release``)::

    persona_codes.schema.json   codebook: {"format": "persona_codes", "columns": [...]}
    data/persona-1m-0000.parquet … persona-1m-0009.parquet   the shards (Zstd)
    data/<source>/….parquet     the producer's own nested layout (also read)
    manifest.json               SHA-256 per file
    sample/sample.parquet       a decoded preview with another schema: never read
    indexes/postings.sqlite, calibration_targets.json, audit.json, RESULTS.md: not used

Only ``data/**/*.parquet`` are shards. ``manifest.json`` (when present) must list
every shard with its SHA-256, and every shard read is checked against it unless
checksum verification is turned off. The manifest's layout is read leniently: a
``files`` list of objects with a path (``path``, ``name`` or ``file``) and a
``sha256``, or an object path → checksum (a hex string or an object holding
``sha256``), at the top level or under ``files``.

``fetch_release("hf://owner/name[@revision]")`` downloads the codebook, the
manifest and the shards with ``huggingface_hub`` (the optional ``hf`` extra) into
its cache; a later call reuses the cache without network. Every shard is fetched:
a seeded sample must see every record.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from ..errors import ConfigError, InputError

CODEBOOK_NAME = "persona_codes.schema.json"
DATA_DIR = "data"
MANIFEST_NAME = "manifest.json"
HF_SCHEME = "hf://"
_HF_PATTERNS = (CODEBOOK_NAME, MANIFEST_NAME, f"{DATA_DIR}/**")
_PATH_KEYS = ("path", "name", "file")


def codebook_path(folder: Path, codebook: str | Path | None = None) -> Path:
    """The codebook: ``codebook`` when given (other layouts), else the release's own."""
    path = Path(codebook).expanduser() if codebook is not None else folder / CODEBOOK_NAME
    if not path.is_file():
        hint = (
            "pass --codebook PATH for a folder laid out otherwise"
            if codebook is None
            else "give the path of the codebook JSON"
        )
        raise InputError(f"{path}: no codebook at this path", hint=hint)
    return path


def find_shards(folder: Path) -> list[Path]:
    """Every ``*.parquet`` below ``folder/data``, sorted by relative path."""
    data = folder / DATA_DIR
    if not data.is_dir():
        raise InputError(
            f"{folder}: no '{DATA_DIR}/' folder of Parquet shards",
            hint="a release folder holds its shards under data/ (sample/ is not read)",
        )
    shards = sorted(data.rglob("*.parquet"), key=lambda p: p.relative_to(folder).as_posix())
    if not shards:
        raise InputError(f"{data}: no Parquet shards (*.parquet)")
    return shards


def read_manifest(folder: Path) -> dict[str, str] | None:
    """Relative path → SHA-256 (lower-case hex) from ``manifest.json``; None when absent."""
    path = folder / MANIFEST_NAME
    if not path.is_file():
        return None
    try:
        doc = json.loads(path.read_text("utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: unreadable release manifest: {exc}") from None
    entries = doc.get("files", doc) if isinstance(doc, dict) else doc
    checksums: dict[str, str] = {}
    if isinstance(entries, list):
        for entry in entries:
            if not isinstance(entry, dict):
                continue
            name = next((entry[k] for k in _PATH_KEYS if k in entry), None)
            if isinstance(name, str) and isinstance(entry.get("sha256"), str):
                checksums[name] = entry["sha256"]
    elif isinstance(entries, dict):
        for name, value in entries.items():
            digest = value.get("sha256") if isinstance(value, dict) else value
            if isinstance(digest, str):
                checksums[name] = digest
    if not checksums:
        raise InputError(f"{path}: no file with a 'sha256' checksum in the manifest")
    return {name.removeprefix("./"): digest.lower() for name, digest in checksums.items()}


def verify_shard(folder: Path, shard: Path, checksums: dict[str, str]) -> None:
    """Raise unless ``shard``'s SHA-256 equals the manifest's."""
    name = shard.relative_to(folder).as_posix()
    hint = "re-download the file, or pass --no-verify-checksums to read it anyway"
    if name not in checksums:
        raise InputError(f"{shard}: not listed in {folder / MANIFEST_NAME}", hint=hint)
    with shard.open("rb") as fh:
        got = hashlib.file_digest(fh, "sha256").hexdigest()
    if got != checksums[name]:
        raise InputError(
            f"{shard}: SHA-256 {got} differs from the manifest's {checksums[name]}", hint=hint
        )


def is_hub_source(source: str) -> bool:
    return str(source).startswith(HF_SCHEME)


def fetch_release(source: str) -> Path:
    """Download (or reuse the cached) codebook, manifest and shards of ``hf://repo[@rev]``."""
    repo, _, revision = source.removeprefix(HF_SCHEME).partition("@")
    offline = (
        f"without network, download the release once and pass its folder: "
        f"--source /path/to/{repo.rpartition('/')[2] or 'release'}"
    )
    if repo.count("/") != 1:
        raise ConfigError(f"{source!r}: expected hf://owner/name[@revision]", hint=offline)
    try:
        import huggingface_hub
    except ImportError:
        raise ConfigError(
            f"{source}: hf:// sources need huggingface_hub (pip install 'popnavshift[hf]')",
            hint=offline,
        ) from None

    def download(local_files_only: bool) -> Path:
        return Path(
            huggingface_hub.snapshot_download(
                repo_id=repo,
                repo_type="dataset",
                revision=revision or None,
                allow_patterns=list(_HF_PATTERNS),
                local_files_only=local_files_only,
            )
        )

    try:  # the cache first: a fetched release needs no network
        return download(local_files_only=True)
    except Exception:  # not (entirely) cached: fetch it
        pass
    try:
        return download(local_files_only=False)
    except Exception as exc:  # the hub raises many types for no network, 404, auth
        reason = (str(exc).splitlines() or [""])[0][:160]
        raise InputError(
            f"{source}: cannot download the release ({type(exc).__name__}: {reason})",
            hint=offline,
        ) from None
