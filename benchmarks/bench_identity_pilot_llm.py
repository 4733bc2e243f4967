"""A real llama-server behind one URL: which changes re-ask the cached records, and what a
pilot projects for the paper's study.

Starts llama.cpp's ``llama-server`` (``--server``) on one loopback port for every step,
always under one ``--alias``, and probes a few personas in one study folder (one cache):

1. the model as given (``-c 8192 -np 2``): every record is asked;
2. the same file restarted with other slots and context (``-c 4096 -np 1``): the
   identity leaves out the server's configuration, so nothing should be asked again;
3. a copy whose weights only are changed (the low bits of two weight tensors; same file
   name, size and metadata), served from another folder: the canary prompts should tell
   it apart, every record asked again, with one line saying why;
4. the first file again: its answers should all come from the cache.

Then ``popnavshift audit STUDY --pilot N`` on the paper's study with this model as its
respondent: the pilot's seconds per call and the projected calls, tokens and time of the
full probe stage. Needs the ``gguf`` package for step 3 (``pip install gguf``).

    python benchmarks/bench_identity_pilot_llm.py --server llama-server \\
        --gguf SmolLM2-135M-Instruct.Q4_1.gguf --pilot 20
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_audit_llm as audit_bench  # noqa: E402  (the llama-server it starts)

POPNAVSHIFT = [sys.executable, "-m", "popnavshift"]
ALIAS = "smollm2-135m-instruct"


@contextlib.contextmanager
def llama_server(binary: str, gguf: Path, port: int, ctx: int, slots: int,
                 log: Path) -> Iterator[str]:
    """``llama-server`` on ``port`` with ``ctx`` and ``slots`` (bench_audit_llm.py's, one
    thread); its ``/v1`` URL."""
    with audit_bench.llama_server(binary, gguf, ALIAS, log, port=port, ctx=ctx, slots=slots,
                                  ready_s=180) as url:
        yield url


def changed_weights(gguf: Path, target: Path) -> list[str]:
    """Copy ``gguf`` to ``target`` with the low bit of every quant byte of two weight
    tensors flipped (a stand-in for a fine-tune: same name, size and metadata)."""
    import numpy as np
    from gguf import GGUFReader

    shutil.copyfile(gguf, target)
    reader = GGUFReader(target, "r+")
    names = [t.name for t in reader.tensors if re.match(r"blk\.[01]\.ffn_down\.weight", t.name)]
    for tensor in reader.tensors:
        if tensor.name in names:
            data = tensor.data.view(np.uint8)
            blocks = data.reshape(-1, 20)  # Q4_1: f16 scale, f16 min, 16 bytes of nibbles
            blocks[:, 4:] ^= 0x11
    reader.data.flush()
    return names


def probe(folder: Path, url: str) -> dict:
    """``popnavshift probe`` of the folder's personas; its calls, cache hits and stderr."""
    cmd = [*POPNAVSHIFT, "probe", "--out", str(folder), "--respondent", "openai",
           "--base-url", url, "--model", ALIAS, "--api-key-env", "none", "--temperature",
           "0", "--concurrency", "1", "--matched-n", "2", "--max-tokens", "400",
           "--extra-body", '{"cache_prompt": false}', "--timeout", "300"]
    t0 = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ,
                                                                   "COLUMNS": "160"})
    if done.returncode != 0:
        raise SystemExit(f"probe failed ({done.returncode}):\n{done.stderr}")
    stats = json.loads((folder / "responses.json").read_text())
    said = [ln for ln in done.stderr.splitlines() if "canary" in ln or "another model" in ln]
    return {"calls": stats["calls"], "cached": stats["cached"], "records": stats["records"],
            "seconds": round(time.perf_counter() - t0, 1), "said": said,
            "model_canaries": stats.get("served", {}).get("model_canaries")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--server", required=True, help="llama-server binary")
    ap.add_argument("--gguf", type=Path, required=True, help="model file (GGUF, Q4_1)")
    ap.add_argument("--personas", type=int, default=6)
    ap.add_argument("--pilot", type=int, default=20, help="personas of the pilot (0: none)")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--no-identity", action="store_true",
                    help="skip steps 1-4 (the pilot only)")
    args = ap.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="bench-identity-"))
    out.mkdir(parents=True, exist_ok=True)
    folder, log, port = out / "study", out / "llama-server.log", audit_bench.free_port()
    summary = out / "identity_pilot.json"
    subprocess.run([*POPNAVSHIFT, "personas", "--n", str(args.personas), "--out",
                    str(folder)], check=True, capture_output=True)
    (out / "changed").mkdir(exist_ok=True)
    changed = out / "changed" / args.gguf.name
    tensors = changed_weights(args.gguf, changed)
    steps = [("first", args.gguf, 8192, 2), ("restart -c 4096 -np 1", args.gguf, 4096, 1),
             ("weights changed", changed, 8192, 2), ("first file again", args.gguf, 8192, 2)]
    steps = [] if args.no_identity else steps
    results: dict = json.loads(summary.read_text()) if summary.exists() else {}
    results |= {"changed_tensors": tensors, "same_size": changed.stat().st_size
                     == args.gguf.stat().st_size}
    for name, gguf, ctx, slots in steps:
        with llama_server(args.server, gguf, port, ctx, slots, log) as url:
            results[name] = probe(folder, url)
        print(name, json.dumps(results[name]), flush=True)
    if args.pilot:
        study = out / "paper-smollm2.yaml"
        with llama_server(args.server, args.gguf, port, 8192, 1, log) as url:
            study.write_text(pilot_study(url))
            t0 = time.perf_counter()
            done = subprocess.run([*POPNAVSHIFT, "audit", str(study), "--pilot",
                                   str(args.pilot), "-o", str(out / "pilot")],
                                  capture_output=True, text=True,
                                  env={**os.environ, "COLUMNS": "160"})
        results["pilot"] = {"seconds": round(time.perf_counter() - t0, 1),
                            "lines": [ln for ln in done.stdout.splitlines()
                                      if ln.startswith(("pilot:", "full study", "second",
                                                        "first respondent"))],
                            "returncode": done.returncode, "error": done.stderr[-2000:]
                            if done.returncode else ""}
        print(json.dumps(results["pilot"], indent=1), flush=True)
    summary.write_text(json.dumps(results, indent=2))
    print(f"→ {summary}")


def pilot_study(url: str) -> str:
    """The paper's study (its personas, matched sample and second respondent) answered by
    the model behind ``url``."""
    from importlib import resources

    text = resources.files("popnavshift").joinpath("studies", "paper.yaml").read_text("utf-8")
    line = (f"respondent: {{name: openai, options: {{base_url: '{url}', model: {ALIAS}, "
            "api_key_env: none, temperature: 0, max_concurrency: 1, max_tokens: 400, "
            "timeout: 300, extra_body: {cache_prompt: false}}}")
    return re.sub(r"(?m)^respondent: .*$", line, text, count=1)


if __name__ == "__main__":
    main()
