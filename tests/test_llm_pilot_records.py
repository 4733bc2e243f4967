"""A respondent's records as a user meets them: a study probed by a llama.cpp-like server
that names its model by a machine path keeps no absolute path in any output, and
`popnavshift audit --pilot` projects the full study from the pace it measured."""

from __future__ import annotations

import json

import pytest

from cli_helpers import cli, tiny_study
from llm_server import Reply, serve

MACHINE = "/home/alice/models"
MODEL_PATH = f"{MACHINE}/SmolLM2-135M-Instruct.Q4_1.gguf"


def llama_like(server) -> None:
    """The server answers as llama.cpp started without --alias: every route names the
    model by its path."""
    listing = {"object": "list", "data": [{"id": MODEL_PATH, "object": "model",
                                           "owned_by": "llamacpp", "meta": {
                                               "n_params": 134515008, "size": 94000000,
                                               "n_ctx": 4096}}]}
    props = {"model_path": MODEL_PATH, "build_info": "b7000", "total_slots": 1}
    server.enqueue_models(*[Reply(raw=json.dumps(listing).encode()),
                            Reply(raw=json.dumps(props).encode())] * 20)
    server.responder = lambda rec: Reply(model=MODEL_PATH)


def respondent_line(server) -> str:
    return (f"respondent: {{name: openai, options: {{base_url: '{server.openai_url}', "
            "model: local, api_key_env: none}}\n")


@pytest.mark.slow
def test_no_output_of_a_probed_study_holds_an_absolute_path(tmp_path):
    with serve() as server:
        llama_like(server)
        study = tiny_study(tmp_path, respondent=respondent_line(server))
        out = tmp_path / "out"
        proc = cli("run", str(study), "-o", str(out), "-w", "1")
        assert proc.returncode == 0, proc.stderr
        assert cli("audit", str(out)).returncode == 0
    files = [p for p in out.rglob("*") if p.is_file()]
    assert {"responses.parquet", "manifest.json", "llm.sqlite", "index.html"} <= {
        p.name for p in files}
    for machine_path in (MACHINE, str(tmp_path), str(tmp_path.resolve())):
        holding = [str(p.relative_to(out)) for p in files
                   if machine_path.encode() in p.read_bytes()]
        assert holding == [], f"{machine_path} in {holding}"
    responses = (out / "responses.json").read_text()
    assert "SmolLM2-135M-Instruct.Q4_1.gguf" in responses  # the file's name is the record


def test_a_pilot_audits_a_few_personas_and_projects_the_full_study(tmp_path):
    with serve() as server:
        study = tmp_path / "study.yaml"
        study.write_text("name: trial\npersonas: {source: synthetic, n: 200}\nmatched_n: 40\n"
                         + respondent_line(server) + "parts: {main: {}}\n")
        proc = cli("audit", str(study), "--pilot", "20", "-o", str(tmp_path / "pilot"))
        assert proc.returncode == 0, proc.stderr
        asked = server.calls
    # 20 personas and 4 matched (40 × 20/200), one valid call each
    assert asked == 24
    lines = proc.stdout.splitlines()
    pilot = next(ln for ln in lines if ln.startswith("pilot:"))
    full = next(ln for ln in lines if ln.startswith("full study:"))
    assert "20 personas, 4 matched, 1 sample(s): 24 records (0 from the cache), 24 calls" in pilot
    # the full study: 200 + 40 records at one call and 120 tokens each (the server's usage)
    assert "240 records (1 sample(s)) → ≈ 240 calls, ≈ 28,800 tokens" in full
    # the scripted server gives every persona one answer: audited as such
    assert "not persona-sensitive — every answer is constant" in proc.stdout
    assert (tmp_path / "pilot" / "cache" / "llm.sqlite").exists()


def test_pilot_options_without_a_pilot_are_refused(tmp_path):
    proc = cli("audit", str(tmp_path), "--samples", "2")
    assert proc.returncode == 2 and "--samples and --out belong to --pilot" in proc.stderr
