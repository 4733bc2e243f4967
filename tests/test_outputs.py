"""Issue 34: outputs of several files are written and read as one (popnavshift.outputs), and
what we read back is one clear error when damaged (popnavshift.io): file sets killed at
any point, folders swapped whole, CSV cells a spreadsheet would run, Markdown and LaTeX
escaping of any label."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from popnavshift.engine.ownership import clean_leftovers
from popnavshift.errors import ConfigError, InputError
from popnavshift.evaluate.export import md_escape, tex_escape, to_latex, to_markdown
from popnavshift.io import csv_text, read_csv, read_json_object
from popnavshift.outputs import (
    FileSet,
    check_writable,
    read_output_manifest,
    replace_folder,
    staging_folder,
    verify,
)


def _card(folder: Path, text: str) -> dict:
    with FileSet(folder, "set.json") as files:
        files.add_text("a.csv", f"x\n{text}\n")
        files.add_text("sub/b.html", f"<p>{text}</p>")
        return files.commit({"kind": "test", "text": text})


def test_a_committed_set_verifies_and_names_what_changed_since(tmp_path):
    doc = _card(tmp_path, "one")
    assert set(doc["files"]) == {"a.csv", "sub/b.html"} and doc["text"] == "one"
    manifest, why = read_output_manifest(tmp_path / "set.json")
    assert why == "" and verify(tmp_path, manifest) == ""
    (tmp_path / "sub" / "b.html").write_text("<p>edited</p>")
    changed = f"{tmp_path / 'sub' / 'b.html'} changed since it was written"
    assert verify(tmp_path, manifest) == changed
    (tmp_path / "a.csv").unlink()
    assert verify(tmp_path, manifest) == f"{tmp_path / 'a.csv'} is missing"
    _card(tmp_path, "two")
    (tmp_path / "extra.txt").write_text("x")
    manifest, _ = read_output_manifest(tmp_path / "set.json")
    assert verify(tmp_path, manifest) == ""  # a file beside it is not part of the set…
    assert "extra.txt was added" in verify(tmp_path, manifest, only=True, ignore=("set.json",))


@pytest.mark.parametrize("text", ["[]", "{", '{"files": [1]}', '{"files": {"../x": "0"}}',
                                  "\xff\xfe"])
def test_a_damaged_manifest_is_a_reason_never_a_traceback(tmp_path, text):
    (tmp_path / "set.json").write_bytes(text.encode("latin-1"))
    manifest, why = read_output_manifest(tmp_path / "set.json")
    assert why or verify(tmp_path, manifest)
    assert str(tmp_path) in (why or str(tmp_path))


def test_a_writer_that_fails_leaves_the_previous_set_untouched(tmp_path):
    before = _card(tmp_path, "old")

    def boom(_tmp: Path) -> None:
        raise RuntimeError("the disk is full")

    with pytest.raises(RuntimeError), FileSet(tmp_path, "set.json") as files:
        files.add_text("a.csv", "x\nnew\n")
        files.add("sub/b.html", boom)
    manifest, why = read_output_manifest(tmp_path / "set.json")
    assert why == "" and manifest == before and verify(tmp_path, manifest) == ""
    assert not list(tmp_path.rglob("*.tmp"))  # nothing staged is left behind


def test_a_set_killed_at_any_point_is_never_taken_for_a_finished_one(tmp_path):
    """A child writes a new set and is killed (SIGKILL) at each step: before its files, in
    the middle of them, between the renames and the manifest. Each time the folder holds
    the old set whole or a set that says it is unfinished, and the leftovers go."""
    _card(tmp_path, "old")
    for stop in ("staging", "renamed"):
        pid = os.fork()
        if pid == 0:  # pragma: no cover - the child
            try:
                files = FileSet(tmp_path, "set.json")
                files.add_text("a.csv", "x\nnew\n")
                if stop == "renamed":
                    (tmp_path / "set.json").unlink()  # as commit does, then is killed
                    os.replace(files._staged.pop("a.csv"), tmp_path / "a.csv")
                time.sleep(30)
            finally:
                os._exit(0)
        time.sleep(0.5)
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        manifest, why = read_output_manifest(tmp_path / "set.json")
        if stop == "staging":
            assert why == "" and verify(tmp_path, manifest) == ""  # the old set, whole
            assert (tmp_path / "a.csv").read_text() == "x\nold\n"
            assert clean_leftovers(tmp_path) == 1
        else:
            assert "set.json is missing" in why  # unfinished: rebuilt, never reused
    assert not list(tmp_path.rglob("*.tmp"))


def test_a_folder_is_swapped_whole(tmp_path):
    target = tmp_path / "report"
    for text in ("old", "new"):
        new = staging_folder(target)
        assert new.name.startswith(".report.") and new.name.endswith(".tmp")
        (new / "index.html").write_text(text)
        replace_folder(new, target)
        assert (target / "index.html").read_text() == text and not new.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report"]
    leftover = staging_folder(target)  # a build killed before its swap
    (leftover / "index.html").write_text("half")
    assert clean_leftovers(tmp_path) == 1 and not leftover.exists()


def test_a_place_that_cannot_be_written_is_refused_before_any_work(tmp_path):
    (tmp_path / "f.txt").write_text("x")
    with pytest.raises(ConfigError, match="is a file, not a folder"):
        check_writable(tmp_path / "f.txt" / "sub", "--out x")
    check_writable(tmp_path / "new" / "deeper", "--out x")
    assert not (tmp_path / "new").exists()  # checked, nothing made


# ---- what we read back --------------------------------------------------------------
@pytest.mark.parametrize("text", ["", "[1, 2]", '"x"', "{", "\x00\xff"])
def test_a_damaged_json_object_is_one_input_error_naming_the_file(tmp_path, text):
    path = tmp_path / "x.json"
    path.write_bytes(text.encode("latin-1"))
    with pytest.raises(InputError, match="x.json is damaged"):
        read_json_object(path)


@pytest.mark.parametrize("raw", [b"", b'a,"b\n', b"\xff\xfe\x00", b"a,b\n1,2,3,4\n5\n"])
def test_a_damaged_csv_is_one_input_error_naming_the_file(tmp_path, raw):
    path = tmp_path / "t.csv"
    path.write_bytes(raw)
    try:
        table = read_csv(path)
    except InputError as err:
        assert "t.csv is damaged" in str(err)
    else:  # pandas reads some of them: then a table, never a traceback
        assert isinstance(table, pd.DataFrame)


FORMULAS = ["=1+1", "+cmd|' /C calc'!A0", "-2+3", "@SUM(A1:A9)", "\tx", "'=x", "''@y", "a=b"]


def test_spreadsheet_formulas_are_inert_in_the_file_and_read_back_as_written(tmp_path):
    df = pd.DataFrame({"controller": FORMULAS, "rate": range(len(FORMULAS))})
    text = csv_text(df)
    cells = pd.read_csv(pd.io.common.StringIO(text))["controller"]
    assert not any(str(c)[:1] in "=+-@\t" for c in cells), list(cells)
    (tmp_path / "t.csv").write_text(text)
    pd.testing.assert_frame_equal(read_csv(tmp_path / "t.csv"), df)


@settings(max_examples=60, deadline=None, database=None)
@given(st.lists(st.text(st.characters(blacklist_categories=("Cs",)), max_size=6), min_size=1,
                max_size=4))
def test_any_text_cell_round_trips_and_never_starts_a_formula(cells):
    df = pd.DataFrame({"name": [c for c in cells if c.strip() == c and c], "n": 1.0})
    if df.empty:
        return
    written = pd.read_csv(pd.io.common.StringIO(csv_text(df)), keep_default_na=False,
                          dtype=str)["name"]
    assert not any(c[:1] in ("=", "+", "-", "@") for c in written)


def _unescaped(text: str, special: str) -> list[str]:
    """The characters of ``special`` in ``text`` not made literal by a backslash (a
    backslash takes the next symbol, or a command's letters and an empty ``{}``)."""
    out, i = [], 0
    while i < len(text):
        ch = text[i]
        if ch == "\\":
            j = i + 1
            while j < len(text) and text[j].isalpha():
                j += 1
            j = j if j > i + 1 else i + 2
            i = j + 2 if text.startswith("{}", j) else j
            continue
        if ch in special:
            out.append(ch)
        i += 1
    return out


@settings(max_examples=80, deadline=None, database=None)
@given(st.text(max_size=20))
def test_markdown_and_latex_cells_carry_no_markup(text):
    md = md_escape(text)
    assert _unescaped(md, "|`*_<>$&~") == [] and "](" not in md and "\n" not in md
    tex = tex_escape(text)
    assert _unescaped(tex, "&%$#_{}~^") == [] and "\n" not in tex


def test_a_hostile_controller_name_is_text_in_every_export():
    t = pd.DataFrame({"controller": ["<script>x</script>", "a|b", "$\\frac{1}{0}$",
                                     "[x](javascript:1)", "=HYPERLINK(\"http://x\")"]})
    md = to_markdown(t)
    assert "<script>" not in md and "\\<script\\>" in md and "](" not in md
    assert "\\$" in md and "a\\|b" in md
    tex = to_latex(t)
    assert "\\$\\textbackslash{}frac\\{1\\}\\{0\\}\\$" in tex
    assert "'=HYPERLINK" in csv_text(t)
