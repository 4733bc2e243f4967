"""The LLM options as a user meets them on the command line (real processes; the server
is a thread of this one): --extra-body, a study's extra_body and samples checked by
`plan`, and -v never passing a server's control characters to the terminal."""

from __future__ import annotations

import json

import pytest

from cli_helpers import assert_one_line_error, cli, tiny_study
from llm_server import Reply, serve

HOSTILE = "\x1b]0;PWNED\x07\x1b[2Jgone"


@pytest.fixture(scope="module")
def personas(tmp_path_factory):
    folder = tmp_path_factory.mktemp("study")
    assert cli("personas", "--n", "12", "--out", str(folder)).returncode == 0
    return folder


def probe(folder, server, *extra):
    return cli("probe", "--respondent", "openai", "--base-url", server.openai_url,
               "--model", "m", "--api-key-env", "none", "--matched-n", "2", "--out",
               str(folder), *extra)


def test_extra_body_on_the_command_line_reaches_every_request(personas):
    with serve() as server:
        proc = probe(personas, server, "--extra-body", '{"cache_prompt": false}')
        assert proc.returncode == 0, proc.stderr
        assert server.calls == 14
        assert {r.body.get("cache_prompt") for r in server.requests} == {False}
    meta = json.loads((personas / "responses.json").read_text())
    assert meta["extra_body"] == {"cache_prompt": False}


@pytest.mark.parametrize(("value", "said"), [
    ("{nope", "--extra-body: not JSON"),
    ('{"n": 3}', "extra_body.n is refused: asks for several completions, all billed"),
    ('["cache_prompt"]', "extra_body must be a mapping of request fields"),
])
def test_a_bad_extra_body_is_one_line_before_any_call(personas, value, said):
    with serve() as server:
        assert_one_line_error(probe(personas, server, "--extra-body", value), said)
        assert server.calls == 0 and server.model_checks == 0


@pytest.mark.parametrize(("respondent", "said"), [
    ("{name: openai, options: {extra_body: cache_prompt, api_key_env: none}}",
     "extra_body must be a mapping of request fields"),
    ("{name: openai, options: {extra_body: [1, 2], api_key_env: none}}",
     "extra_body must be a mapping of request fields"),
    ("{name: openai, options: {extra_body: {stream: true}, api_key_env: none}}",
     "extra_body.stream is refused"),
    ("{name: rule, samples: true}", "respondent.samples: Input should be a valid integer"),
])
def test_plan_refuses_a_bad_respondent_in_one_line(tmp_path, respondent, said):
    study = tiny_study(tmp_path, respondent=f"respondent: {respondent}\n")
    assert_one_line_error(cli("plan", str(study)), said)


def test_verbose_never_passes_a_server_s_control_characters(personas):
    with serve() as server:
        server.responder = lambda rec: Reply(status=400, raw=json.dumps(
            {"error": {"message": HOSTILE}}).encode())
        proc = cli("-v", "probe", "--respondent", "openai", "--base-url", server.openai_url,
                   "--model", "m", "--api-key-env", "none", "--matched-n", "2",
                   "--max-failures", "50", "--out", str(personas))
    assert proc.returncode == 2
    assert "\x1b" not in proc.stderr and "\x07" not in proc.stderr
    assert "\\x1b]0;PWNED" in proc.stderr  # shown, as its codes


def test_llm_options_with_the_rule_respondent_are_refused_not_dropped(tmp_path):
    proc = cli("probe", "-o", str(tmp_path / "s"), "--respondent", "rule", "--extra-body",
               '{"stream": true}', "--model-sha256", "abc", "--concurrency", "3")
    assert_one_line_error(proc, "--respondent rule takes no LLM option")
    assert "--extra-body" in proc.stderr and "--concurrency" in proc.stderr
    assert not (tmp_path / "s" / "responses.parquet").exists()
