"""The MatrAIx release reader on tiny release folders laid out as published (fixtures_matraix)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fixtures_matraix import (
    MINORS,
    adult_ids,
    codebook_doc,
    codebook_fields,
    make_records,
    pack_record,
    shard_table,
    write_release,
)
from popnavshift.errors import ConfigError, InputError
from popnavshift.personas.codebook import is_minor_bracket
from popnavshift.personas.fields import PERSONA_FIELDS, vocabulary
from popnavshift.personas.flat import sample_key
from popnavshift.personas.load import load_personas
from popnavshift.personas.matraix import Codebook, decode_batch, read_codebook, read_release
from popnavshift.tables import check_table

FIELDS = codebook_fields()
CODEBOOK = "persona_codes.schema.json"


@pytest.fixture
def recs() -> list[dict]:
    return make_records(60)


def ids(table: pd.DataFrame) -> list[str]:
    return list(table["persona_id"])


def by_id(recs: list[dict]) -> dict[str, dict]:
    return {r["persona_id"]: r for r in recs}


def test_full_read_decodes_every_field_and_skips_minors(tmp_path, recs):
    table, prov = load_personas(str(write_release(tmp_path / "rel", recs)), n=None)
    check_table(table, "personas")
    assert ids(table) == adult_ids(recs)
    expected = pd.DataFrame(recs).set_index("persona_id").loc[ids(table)]
    for field in PERSONA_FIELDS:
        assert list(table[field]) == list(expected[field]), field
    assert list(table["source"]) == list(expected["source"])
    assert prov["kind"] == "matraix"
    assert prov["codebook_format"] == "persona_codes v2"
    assert prov["records_scanned"] == 60
    assert prov["records_excluded_minor"] == 2
    assert prov["checksums"] == "verified against manifest.json"
    assert prov["shards"] == [f"data/persona-1m-000{s}.parquet" for s in range(3)]
    assert prov["scanned_per_source"] == {s: 12 for s in ("amazon", "gss", "stackoverflow",
                                                          "synthetic", "wiki")}
    assert prov["source_mix"] == {"amazon": 12, "gss": 12, "stackoverflow": 10,
                                  "synthetic": 12, "wiki": 12}


def test_persona_id_is_source_and_record_id_whatever_the_layout(tmp_path, recs):
    flat = load_personas(str(write_release(tmp_path / "a", recs)), n=None)[0]
    nested_folder = write_release(tmp_path / "b", recs, nested=True, n_shards=2)
    nested, prov = load_personas(str(nested_folder), n=None)
    assert ids(flat) == ids(nested)
    assert "gss:r00001" in set(ids(flat))
    assert "data/gss/part-0001.parquet" in prov["shards"]
    pd.testing.assert_frame_equal(flat, nested)


def test_sample_preview_and_other_release_files_are_not_read(tmp_path, recs):
    folder = write_release(tmp_path / "rel", recs)
    assert (folder / "sample" / "sample.parquet").is_file()
    table, prov = load_personas(str(folder), n=None)
    assert not any(s.startswith("sample/") for s in prov["shards"])
    assert len(table) == 58


def test_rows_are_sparse_like_the_release(recs):
    populated = {}
    for r in recs:
        _, bitmap, _ = pack_record(r, FIELDS)
        bits = np.frombuffer(bitmap or bytes(162), np.uint8)
        missing = np.unpackbits(bits, bitorder="little")[: len(FIELDS)]
        populated.setdefault(r["source"], []).append(len(FIELDS) - int(missing.sum()))
    assert max(populated["gss"]) < 40 < min(populated["wiki"])
    assert set(populated["synthetic"]) == {len(FIELDS)}


def test_fixture_has_the_published_widths(tmp_path, recs):
    folder = write_release(tmp_path / "rel", recs)
    schema = pq.read_schema(folder / "data" / "persona-1m-0000.parquet")
    assert schema.field("attributes").type == pa.binary(645)
    assert schema.field("null_bitmap").type == pa.binary(162)
    assert "persona_id" not in schema.names
    doc = json.loads((folder / CODEBOOK).read_text())
    assert doc["format"] == "persona_codes" and len(doc["columns"]) == 1290


def test_slots_follow_the_codebook_order_not_ours():
    slots = {f["id"]: i for i, f in enumerate(FIELDS)}
    assert [f for f in slots if f in PERSONA_FIELDS] != list(PERSONA_FIELDS)


@settings(max_examples=40, deadline=None)
@given(st.data())
def test_nibble_packing_round_trips(data):
    fields = codebook_fields(order_seed=data.draw(st.integers(0, 50)))
    record = {"source": "wiki", "source_record_id": "r00001"}
    for field in PERSONA_FIELDS:
        record[field] = data.draw(st.sampled_from([*vocabulary(field), None]))
    batch = shard_table([record], fields).to_batches()[0]
    slots = {f["id"]: i for i, f in enumerate(fields) if f["id"] in PERSONA_FIELDS}
    values = {f["id"]: tuple(f["values"]) for f in fields if f["id"] in PERSONA_FIELDS}
    decoded = decode_batch(batch, Codebook(None, len(fields), slots, values), "mem", 1)
    assert decoded.loc[0, "persona_id"] == "wiki:r00001"
    for field in PERSONA_FIELDS:
        got = decoded.loc[0, field]
        assert (None if pd.isna(got) else got) == record[field], field


def with_missing(recs: list[dict]) -> list[dict]:
    recs[4]["trust_level"] = None  # shard 0, row 5; no schema default
    recs[25]["health_mobility"] = None  # shard 1, row 6; default "Full"
    recs[30]["cog_decision_speed"] = None  # optional
    return recs


def test_null_bitmap_marks_missing_and_require_drops(tmp_path, recs):
    folder = write_release(tmp_path / "rel", with_missing(recs))
    table, prov = load_personas(str(folder), n=None)
    assert len(table) == 56
    assert prov["records_dropped_missing"] == 2
    assert pd.isna(table.set_index("persona_id").loc["amazon:r00030", "cog_decision_speed"])


def test_sparse_gss_rows_lacking_needed_fields_are_dropped_and_counted(tmp_path, recs):
    for r in recs:
        if r["source"] == "gss" and int(r["source_record_id"][1:]) % 2:
            r["cog_patience"] = r["att_automation"] = None
    table, prov = load_personas(str(write_release(tmp_path / "rel", recs)), n=None)
    assert prov["records_dropped_missing"] == 6
    assert prov["usable_per_source"]["gss"] == 6
    assert prov["source_mix"]["gss"] == 6


def test_sources_restrict_the_sample_and_a_typo_is_named(tmp_path, recs):
    folder = write_release(tmp_path / "rel", recs)
    table, prov = load_personas(str(folder), n=None, sources=["wiki", "gss"])
    assert set(table["source"]) == {"wiki", "gss"}
    assert prov["records_other_source"] == 36
    assert prov["sources"] == ["gss", "wiki"]
    with pytest.raises(InputError, match=r"no record of source\(s\) wikki .*wiki"):
        load_personas(str(folder), n=None, sources=["wikki"])


def test_error_policy_names_shard_row_and_field(tmp_path, recs):
    folder = write_release(tmp_path / "rel", with_missing(recs))
    with pytest.raises(
        InputError, match=r"persona-1m-0000\.parquet: row 5: required field 'trust_level'"
    ):
        load_personas(str(folder), n=None, missing="error")


def test_fill_policy_fills_defaults_or_names_the_field(tmp_path, recs):
    recs[25]["health_mobility"] = None
    folder = write_release(tmp_path / "rel", recs)
    table, prov = load_personas(str(folder), n=None, missing="fill")
    assert table.set_index("persona_id").loc["amazon:r00025", "health_mobility"] == "Full"
    assert prov["values_filled"] == 1
    recs[4]["trust_level"] = None
    folder = write_release(tmp_path / "rel2", recs)
    with pytest.raises(
        InputError, match=r"row 5: required field 'trust_level' .*no schema default"
    ):
        load_personas(str(folder), n=None, missing="fill")


def test_overridden_fields_are_missing(tmp_path, recs):
    recs[1]["time_pressure"] = "Late for a flight"  # outside the codebook: an override
    recs[2]["cog_decision_speed"] = "Depends on mood"  # optional field
    folder = write_release(tmp_path / "rel", recs)
    assert pack_record(recs[1], FIELDS)[2] is not None
    table, prov = load_personas(str(folder), n=None)
    assert "gss:r00001" not in set(ids(table))
    assert prov["records_dropped_missing"] == 1
    assert pd.isna(table.set_index("persona_id").loc["stackoverflow:r00002", "cog_decision_speed"])


def test_minor_brackets():
    assert [is_minor_bracket(b) for b in ("Under 5", "5-12", "13-17", "18-24", "65+")] == [
        True, True, True, False, False
    ]
    with pytest.raises(InputError, match="age_bracket value 'teen' is not an age range"):
        is_minor_bracket("teen")


def test_a_record_without_an_age_bracket_is_kept(tmp_path, recs):
    recs[7]["age_bracket"] = None
    table, prov = load_personas(str(write_release(tmp_path / "rel", recs)), n=None)
    assert "stackoverflow:r00007" in set(ids(table))
    assert prov["records_excluded_minor"] == 1
    assert MINORS[12] == "13-17"


def test_sample_is_deterministic_and_independent_of_shard_layout(tmp_path, recs):
    a = write_release(tmp_path / "a", recs, n_shards=3)
    b = write_release(tmp_path / "b", list(reversed(recs)), n_shards=2, nested=True)
    sample_a = ids(load_personas(str(a), n=15, seed=11)[0])
    assert sample_a == ids(load_personas(str(a), n=15, seed=11)[0])
    assert sample_a == ids(load_personas(str(b), n=15, seed=11)[0])
    expected = sorted(sorted(adult_ids(recs), key=lambda p: (sample_key(11, p), p))[:15])
    assert sample_a == expected
    assert sample_a != ids(load_personas(str(a), n=15, seed=12)[0])


def test_release_and_flat_table_give_the_same_sample(tmp_path, recs):
    folder = write_release(tmp_path / "rel", recs)
    flat = tmp_path / "same.parquet"
    adults = set(adult_ids(recs))
    pd.DataFrame([r for r in recs if r["persona_id"] in adults]).to_parquet(flat, index=False)
    release_table = load_personas(str(folder), n=9, seed=2)[0]
    flat_table = load_personas(str(flat), n=9, seed=2)[0]
    assert ids(release_table) == ids(flat_table)
    cols = list(PERSONA_FIELDS)
    pd.testing.assert_frame_equal(release_table[cols], flat_table[cols])


def test_streams_in_batches_of_the_given_size_reading_only_needed_columns(
    tmp_path, recs, monkeypatch
):
    folder = write_release(tmp_path / "rel", recs)
    calls, sizes = [], []
    original = pq.ParquetFile.iter_batches

    def spy(self, *args, **kwargs):
        calls.append(kwargs)
        for batch in original(self, *args, **kwargs):
            sizes.append(batch.num_rows)
            yield batch

    def no_full_read(*args, **kwargs):
        raise AssertionError("read_table must not be used on a release")

    monkeypatch.setattr(pq.ParquetFile, "iter_batches", spy)
    monkeypatch.setattr(pq, "read_table", no_full_read)
    table, prov = read_release(folder, n=5, seed=0, batch_size=7)
    assert len(table) == 5
    assert len(calls) == 3
    assert {c["batch_size"] for c in calls} == {7}
    assert set(calls[0]["columns"]) == {
        "source",
        "source_row_index",
        "source_record_id",
        "attributes",
        "null_bitmap",
        "attribute_overrides",
    }
    assert max(sizes) == 7
    assert sum(sizes) == 60
    assert prov["batch_size"] == 7


@pytest.mark.parametrize("batch_size", [0, -1, 2.5])
def test_invalid_batch_size_is_a_config_error(tmp_path, recs, batch_size):
    folder = write_release(tmp_path / "rel", recs)
    with pytest.raises(ConfigError, match="batch_size must be a positive integer"):
        read_release(folder, n=5, seed=0, batch_size=batch_size)


def test_manifest_checksum_mismatch_names_the_shard_unless_turned_off(tmp_path, recs):
    folder = write_release(tmp_path / "rel", recs)
    shard = folder / "data" / "persona-1m-0001.parquet"
    pq.write_table(shard_table(recs[20:39], FIELDS), shard)  # one record fewer
    with pytest.raises(InputError, match=r"persona-1m-0001\.parquet: SHA-256 [0-9a-f]{64} differs"):
        load_personas(str(folder), n=10)
    table, prov = load_personas(str(folder), n=None, verify_checksums=False)
    assert prov["checksums"] == "not verified (turned off)"
    assert prov["records_scanned"] == 59


def test_shard_missing_from_the_manifest_and_no_manifest(tmp_path, recs):
    folder = write_release(tmp_path / "rel", recs)
    pq.write_table(shard_table(recs[:1], FIELDS), folder / "data" / "extra.parquet")
    with pytest.raises(InputError, match=r"extra\.parquet: not listed in .*manifest\.json"):
        load_personas(str(folder), n=10)
    folder = write_release(tmp_path / "bare", recs, manifest=False)
    assert load_personas(str(folder), n=10)[1]["checksums"] == "no manifest.json"


def test_garbage_shard_names_the_file(tmp_path, recs):
    folder = write_release(tmp_path / "rel", recs, manifest=False)
    (folder / "data" / "persona-1m-0001.parquet").write_bytes(b"PAR1 but not really")
    with pytest.raises(InputError, match=r"persona-1m-0001\.parquet: unreadable Parquet shard"):
        load_personas(str(folder), n=10)


def test_shard_without_attributes_names_file_and_column(tmp_path, recs):
    folder = write_release(tmp_path / "rel", recs, manifest=False)
    pq.write_table(
        shard_table(recs[:2], FIELDS).drop(["attributes"]), folder / "data" / "x-0009.parquet"
    )
    with pytest.raises(
        InputError, match=r"x-0009\.parquet: shard lacks column\(s\) attributes"
    ):
        load_personas(str(folder), n=10)


def write_raw_shard(folder, attributes, type_=pa.binary()) -> None:
    table = shard_table(make_records(2), FIELDS).drop(["attributes", "null_bitmap"])
    table = table.append_column("attributes", pa.array(attributes, type_))
    pq.write_table(table, folder / "data" / "x-0009.parquet")


def test_short_attributes_name_file_and_row(tmp_path, recs):
    folder = write_release(tmp_path / "rel", recs, manifest=False)
    full = pack_record(recs[0], FIELDS)[0]
    write_raw_shard(folder, [full, full[:3]])
    with pytest.raises(
        InputError, match=r"x-0009\.parquet: row 2: 'attributes' has 3 byte\(s\)"
    ):
        load_personas(str(folder), n=10)


def test_code_out_of_range_names_file_row_and_field(tmp_path, recs):
    folder = write_release(tmp_path / "rel", recs, manifest=False)
    slot = next(i for i, f in enumerate(FIELDS) if f["id"] == "time_pressure")
    bad = bytearray(pack_record(recs[0], FIELDS)[0])
    bad[slot // 2] |= 0x0E << (4 * (slot % 2))  # code ≥ 14 for a 4-value field
    write_raw_shard(folder, [pack_record(recs[1], FIELDS)[0], bytes(bad)])
    with pytest.raises(
        InputError, match=r"x-0009\.parquet: row 2: field 'time_pressure' has code 1[45]"
    ):
        load_personas(str(folder), n=10)


def test_attributes_of_the_wrong_type(tmp_path, recs):
    folder = write_release(tmp_path / "rel", recs, manifest=False)
    write_raw_shard(folder, ["ab", "cd"], pa.string())
    with pytest.raises(InputError, match="column 'attributes' should be binary, got string"):
        load_personas(str(folder), n=10)


def test_duplicate_ids_across_shards_name_both_places(tmp_path, recs):
    recs[45]["source"], recs[45]["source_record_id"] = recs[3]["source"], "r00003"
    folder = write_release(tmp_path / "rel", recs)
    with pytest.raises(
        InputError,
        match=r"duplicate persona id 'synthetic:r00003' in data/persona-1m-0000\.parquet row 4 "
        r"and data/persona-1m-0002\.parquet row 6",
    ):
        load_personas(str(folder), n=None)


@pytest.mark.parametrize(
    "doc",
    [
        FIELDS,
        {"fields": FIELDS},
        {"fields": [{"name": f["id"], "levels": dict(enumerate(f["values"]))} for f in FIELDS]},
    ],
)
def test_other_codebook_layouts_via_an_explicit_codebook(tmp_path, recs, doc):
    doc = json.loads(json.dumps(doc))  # code keys become strings, as in a real JSON file
    folder = write_release(tmp_path / "rel", recs, manifest=False)
    (folder / CODEBOOK).unlink()
    (tmp_path / "book.json").write_text(json.dumps(doc), "utf-8")
    with pytest.raises(InputError, match=r"persona_codes\.schema\.json: no codebook .*--codebook"):
        load_personas(str(folder), n=None)
    table, prov = load_personas(str(folder), n=None, codebook=tmp_path / "book.json")
    assert len(table) == 58
    assert prov["codebook"] == str(tmp_path / "book.json")


def test_codebook_of_another_format_is_refused(tmp_path, recs):
    folder = write_release(tmp_path / "rel", recs, codebook={"format": "dims", "columns": FIELDS})
    with pytest.raises(InputError, match="codebook format 'dims', expected 'persona_codes'"):
        load_personas(str(folder), n=10)


def test_codebook_values_map_ignoring_case(tmp_path, recs):
    fields = json.loads(json.dumps(FIELDS))
    tp = next(f for f in fields if f["id"] == "time_pressure")
    tp["values"] = [v.lower() for v in tp["values"]]
    folder = write_release(tmp_path / "rel", recs, codebook=codebook_doc(fields))
    assert read_codebook(folder / CODEBOOK).values["time_pressure"] == tuple(
        reversed(vocabulary("time_pressure"))
    )


def test_codebook_value_outside_our_vocabulary_names_field_and_value(tmp_path, recs):
    fields = json.loads(json.dumps(FIELDS))
    next(f for f in fields if f["id"] == "trust_level")["values"][1] = "Paranoid"
    folder = write_release(tmp_path / "rel", recs, codebook=codebook_doc(fields))
    with pytest.raises(
        InputError, match=r"field 'trust_level': codebook value 'Paranoid' is not in our vocabulary"
    ):
        load_personas(str(folder), n=10)


def test_codebook_lacking_a_required_field(tmp_path, recs):
    fields = [f for f in FIELDS if f["id"] != "cog_patience"]
    folder = write_release(tmp_path / "rel", recs, codebook=codebook_doc(fields))
    with pytest.raises(
        InputError, match=r"schema\.json: codebook lacks required field\(s\) cog_patience"
    ):
        load_personas(str(folder), n=10)


def test_unparsable_codebook(tmp_path, recs):
    folder = write_release(tmp_path / "rel", recs)
    (folder / CODEBOOK).write_text("{not json", "utf-8")
    with pytest.raises(InputError, match="unreadable codebook"):
        load_personas(str(folder), n=10)


def test_folder_without_shards_and_nonexistent_folder(tmp_path):
    folder = tmp_path / "rel"
    folder.mkdir()
    (folder / CODEBOOK).write_text(json.dumps(codebook_doc(FIELDS)), "utf-8")
    with pytest.raises(InputError, match=r"no 'data/' folder of Parquet shards"):
        load_personas(str(folder), n=10)
    (folder / "data").mkdir()
    with pytest.raises(InputError, match=r"data: no Parquet shards"):
        load_personas(str(folder), n=10)
    with pytest.raises(ConfigError, match="neither 'synthetic' nor an existing"):
        load_personas(str(tmp_path / "absent"))
    with pytest.raises(InputError, match="no such release folder"):
        read_release(tmp_path / "absent", n=10, seed=0)


def test_release_options_on_other_sources_are_a_config_error(tmp_path):
    with pytest.raises(ConfigError, match="apply to a MatrAIx release only"):
        load_personas("synthetic", n=10, sources=["gss"])


def test_too_few_complete_records_is_an_error(tmp_path, recs):
    folder = write_release(tmp_path / "rel", with_missing(recs))
    with pytest.raises(
        InputError,
        match=r"57 persona record\(s\) requested but only 56 usable \(60 scanned, 2 dropped",
    ):
        load_personas(str(folder), n=57)
    assert np.array_equal(
        load_personas(str(folder), n=56)[0]["persona_id"],
        load_personas(str(folder), n=None)[0]["persona_id"],
    )


HUB = "hf://MatrAIx2026/MatrAIx_Persona_1M_Public_Release"


def test_hub_source_without_network_names_the_offline_alternative(monkeypatch):
    huggingface_hub = pytest.importorskip("huggingface_hub")
    calls = []

    def offline(**kwargs):
        calls.append(kwargs)
        raise OSError("Name or service not known\nsecond line")

    monkeypatch.setattr(huggingface_hub, "snapshot_download", offline)
    with pytest.raises(InputError) as err:
        load_personas(HUB, n=10)
    assert "cannot download the release (OSError: Name or service not known)" in str(err.value)
    assert "--source /path/to/MatrAIx_Persona_1M_Public_Release" in str(err.value)
    assert "\n" not in str(err.value)
    assert [c.get("local_files_only", False) for c in calls] == [True, False]


def test_hub_source_fetches_codebook_manifest_and_shards_only(tmp_path, recs, monkeypatch):
    huggingface_hub = pytest.importorskip("huggingface_hub")
    folder = write_release(tmp_path / "cache", recs)
    calls = []

    def cached(**kwargs):
        calls.append(kwargs)
        return str(folder)

    monkeypatch.setattr(huggingface_hub, "snapshot_download", cached)
    table, prov = load_personas(HUB + "@v1", n=None)
    assert ids(table) == adult_ids(recs)
    assert calls[0]["repo_id"] == "MatrAIx2026/MatrAIx_Persona_1M_Public_Release"
    assert calls[0]["repo_type"] == "dataset" and calls[0]["revision"] == "v1"
    assert calls[0]["allow_patterns"] == [CODEBOOK, "manifest.json", "data/**"]


def test_hub_source_without_huggingface_hub_says_how_to_install(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "huggingface_hub", None)
    with pytest.raises(ConfigError, match=r"pip install 'popnavshift\[hf\]'.*--source /path/to/"):
        load_personas(HUB, n=10)


def test_cli_decodes_a_release_laid_out_as_published(tmp_path, recs):
    from forked_cli import run_cli

    recs[1]["time_pressure"] = "Late for a flight"  # an override: gss:r00001 lacks it
    folder = write_release(tmp_path / "rel", recs, nested=True, n_shards=2)
    out = tmp_path / "study"

    def cli(*args):  # forked: a real process without the start-up
        return run_cli("personas", "--source", str(folder), "--out", str(out), *args)

    proc = cli("--n", "57", "--seed", "4")
    assert proc.returncode == 0, proc.stderr
    table = pd.read_parquet(out / "personas.parquet")
    expected = [p for p in adult_ids(recs) if p != "gss:r00001"]
    assert list(table["persona_id"]) == expected
    truth = pd.DataFrame(recs).set_index("persona_id").loc[expected]
    for field in PERSONA_FIELDS:
        assert list(table[field]) == list(truth[field]), field
    prov = json.loads((out / "personas.json").read_text())
    assert prov["records_excluded_minor"] == 2 and prov["records_dropped_missing"] == 1
    assert prov["source_mix"]["stackoverflow"] == 10
    assert cli("--n", "10", "--only-source", "gss").returncode == 0
    assert set(pd.read_parquet(out / "personas.parquet")["source"]) == {"gss"}
    (folder / "data" / "wiki" / "part-0001.parquet").write_bytes(b"tampered")
    proc = cli("--n", "10")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "part-0001.parquet: SHA-256" in lines[0], proc.stderr
    proc = cli("--n", "10", "--no-verify-checksums")
    assert proc.returncode == 2 and "unreadable Parquet shard" in proc.stderr


def test_a_study_file_passes_the_release_policy_to_the_persona_stage(tmp_path, recs):
    from popnavshift.design.specs import PersonaSource
    from popnavshift.design.study import study_from_dict
    from popnavshift.engine.runner import population_settings
    from popnavshift.engine.stages import stage_stamps
    from popnavshift.hashing import digest
    from popnavshift.pipeline import PopulationSettings, run_personas

    folder = write_release(tmp_path / "rel", recs)
    personas = {"source": str(folder), "n": 10, "sources": ["wiki", "gss"],
                "verify_checksums": False}
    study = study_from_dict({"name": "s", "personas": personas, "parts": {"main": {}}})
    settings = population_settings(study)
    assert settings.personas is study.personas
    assert (settings.personas.sources, settings.personas.verify_checksums) == (("wiki", "gss"),
                                                                            False)
    table = run_personas(tmp_path, settings)
    assert set(table["source"]) == {"wiki", "gss"}
    # the default policy leaves an existing study's stamp as it was
    plain = PopulationSettings()
    assert stage_stamps(plain)["personas"] == digest(["personas", "synthetic", 600, 0,
                                                       "require"])
    assert stage_stamps(settings)["personas"] != stage_stamps(
        PopulationSettings(PersonaSource(source=str(folder), n=10))
    )["personas"]
