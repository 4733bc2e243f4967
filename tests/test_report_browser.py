"""The report in a real headless browser (Chromium): no console or network errors, the
figures decode and show, the tables have rows, and a screenshot is not blank.

Chromium is driven over ``--remote-debugging-pipe`` (the DevTools protocol on file
descriptors 3 and 4), so no port is opened. Skipped, with the reason, when no
Chromium binary is found.
"""

from __future__ import annotations

import json
import os
import select
import shutil
import subprocess
import time
from pathlib import Path

import pytest

from popnavshift.design.study import study_from_dict
from report_study import STUDY

CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--hide-scrollbars")
TIMEOUT = 60.0  # [s] for any one browser step


def chromium() -> str | None:
    found = [shutil.which(c) for c in CANDIDATES] + ["/usr/bin/chromium"]
    return next((p for p in found if p and os.access(p, os.X_OK)), None)


BROWSER = chromium()
pytestmark = [pytest.mark.slow, pytest.mark.skipif(
    BROWSER is None, reason="no Chromium found (apt-get install -y chromium); "
    f"looked for {', '.join(CANDIDATES)} and /usr/bin/chromium")]


@pytest.fixture
def page(reported_study) -> Path:
    """The report of test_report.py's small study (report_study.py), built once a session."""
    return reported_study / "report" / "index.html"


class DevTools:
    """A minimal DevTools-protocol client over Chromium's debugging pipe."""

    def __init__(self, profile: Path) -> None:
        to_child, self._to_browser = os.pipe()
        self._from_browser, from_child = os.pipe()

        def wire() -> None:  # the browser reads commands on fd 3 and writes on fd 4
            # copy first: either pipe end may itself be fd 3 or 4 (dup2 onto itself would
            # keep it close-on-exec, and the first dup2 could overwrite the other end)
            ends = os.dup(to_child), os.dup(from_child)
            for fd, end in zip((3, 4), ends, strict=True):
                os.dup2(end, fd)
                os.set_inheritable(fd, True)

        self.proc = subprocess.Popen(
            [BROWSER, *FLAGS, "--remote-debugging-pipe", f"--user-data-dir={profile}",
             "about:blank"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, preexec_fn=wire,
            close_fds=False)
        os.close(to_child)
        os.close(from_child)
        self._buffer = b""
        self._next_id = 0
        self.events: list[dict] = []

    def _read(self, deadline: float) -> dict:
        while b"\0" not in self._buffer:
            ready, _, _ = select.select([self._from_browser], [], [], deadline - time.time())
            if not ready:
                raise TimeoutError("no answer from Chromium")
            chunk = os.read(self._from_browser, 1 << 20)
            if not chunk:
                raise EOFError("Chromium closed the pipe")
            self._buffer += chunk
        message, self._buffer = self._buffer.split(b"\0", 1)
        return json.loads(message)

    def call(self, method: str, session: str | None = None, **params) -> dict:
        self._next_id += 1
        msg: dict = {"id": self._next_id, "method": method, "params": params}
        if session:
            msg["sessionId"] = session
        os.write(self._to_browser, json.dumps(msg).encode() + b"\0")
        deadline = time.time() + TIMEOUT
        while True:
            reply = self._read(deadline)
            if reply.get("id") == self._next_id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})
            self.events.append(reply)

    def wait_for(self, method: str) -> dict:
        deadline = time.time() + TIMEOUT
        for event in self.events:
            if event.get("method") == method:
                return event
        while True:
            event = self._read(deadline)
            self.events.append(event)
            if event.get("method") == method:
                return event

    def close(self) -> None:
        try:
            self.call("Browser.close")
        finally:
            self.proc.wait(timeout=TIMEOUT)
            os.close(self._to_browser)
            os.close(self._from_browser)


PROBE = """JSON.stringify({
  images: Array.from(document.images).map(i => ({
    data: i.src.startsWith("data:image/png;base64,"), ok: i.complete && i.naturalWidth > 0,
    shown: i.getBoundingClientRect().width})),
  tables: Array.from(document.querySelectorAll("table")).map(
    t => t.querySelectorAll("tbody tr").length),
  sections: Array.from(document.querySelectorAll("section")).map(s => s.id),
  scripts: document.scripts.length,
  respondent: document.getElementById("respondent-note").textContent,
  overflow: document.documentElement.scrollWidth - document.documentElement.clientWidth,
})"""


def load(page: Path, probe: str, profile: Path) -> tuple[dict, list[dict]]:
    """Open ``page`` in Chromium: the DOM facts ``probe`` (a JS expression giving JSON)
    returns, and every console message, exception, error or warning logged."""
    browser = DevTools(profile)
    try:
        target = next(t for t in browser.call("Target.getTargets")["targetInfos"]
                      if t["type"] == "page")
        session = browser.call("Target.attachToTarget", targetId=target["targetId"],
                               flatten=True)["sessionId"]
        for domain in ("Page", "Runtime", "Log"):
            browser.call(f"{domain}.enable", session)
        browser.call("Page.navigate", session, url=page.as_uri())
        browser.wait_for("Page.loadEventFired")
        result = browser.call("Runtime.evaluate", session, expression=probe, returnByValue=True)
        dom = json.loads(result["result"]["value"])
    finally:
        browser.close()
    problems = [e["params"] for e in browser.events if e.get("method") in (
        "Runtime.consoleAPICalled", "Runtime.exceptionThrown")]
    problems += [e["params"]["entry"] for e in browser.events
                 if e.get("method") == "Log.entryAdded"
                 and e["params"]["entry"]["level"] in ("error", "warning")]
    return dom, problems


def test_page_loads_without_errors_and_shows_figures_and_tables(page, tmp_path):
    dom, problems = load(page, PROBE, tmp_path / "profile")
    assert problems == []
    assert dom["scripts"] == 0
    assert len(dom["images"]) == 8  # Table I, Fig. 2–4, τ, trade-off and the null figure
    assert all(i["data"] and i["ok"] and i["shown"] > 300 for i in dom["images"]), dom["images"]
    assert len(dom["tables"]) >= 10 and min(dom["tables"]) >= 1
    assert dom["overflow"] <= 0  # a wide table scrolls in its box, not the page sideways
    # the answer first, then the respondent audit, the populations and the checks before
    # any score
    assert dom["sections"][:9] == ["answer", "ranks", "pairs", "replicates", "calibration",
                                   "audit", "populations", "checks", "summary"]
    assert "NOT a language model" in dom["respondent"]


def test_dump_dom_has_no_console_lines_and_a_screenshot_is_not_blank(page, tmp_path):
    from PIL import Image

    common = [BROWSER, *FLAGS, f"--user-data-dir={tmp_path / 'profile'}"]
    dump = subprocess.run([*common, "--enable-logging=stderr", "--v=0", "--dump-dom",
                           page.as_uri()], capture_output=True, text=True, timeout=TIMEOUT)
    assert dump.returncode == 0, dump.stderr[-2000:]
    assert [ln for ln in dump.stderr.splitlines() if ":CONSOLE" in ln] == []
    assert dump.stdout.count('src="data:image/png;base64,') == 8
    assert "Table I" in dump.stdout and dump.stdout.count("<tr>") > 40
    shot = tmp_path / "report.png"
    subprocess.run([*common, f"--screenshot={shot}", "--window-size=1280,4000", page.as_uri()],
                   capture_output=True, timeout=TIMEOUT, check=True)
    image = Image.open(shot).convert("RGB")
    assert image.size == (1280, 4000)
    colours = image.resize((320, 1000)).getcolors(maxcolors=1 << 16)
    assert colours is not None and len(colours) > 200  # text, tables and figures, not blank
    keep = os.environ.get("POPNAVSHIFT_SCREENSHOT")  # to look at it: set to a file path
    if keep:
        shutil.copyfile(shot, keep)


# ---- the compare page (synthetic tables: no simulation) -----------------------------------
COMPARE_PROBE = """JSON.stringify({
  images: Array.from(document.images).map(i => ({ok: i.complete && i.naturalWidth > 0,
    shown: i.getBoundingClientRect().width})),
  rows: Array.from(document.querySelectorAll("table tr")).length,
  scripts: document.scripts.length,
})"""


def test_the_compare_page_loads_without_console_errors(tmp_path):
    from popnavshift.evaluate.compare import Comparison, compare_table
    from popnavshift.evaluate.compare_page import write_comparison
    from popnavshift.read.access import EVALUATE_DIR
    from synth_study import no_effect, synthetic_study

    ctrls = ("reactive", "HRVO", "<b>odd & name</b>")  # escaped, not markup
    runs, peds = synthetic_study({"p1": no_effect, "p2": no_effect}, n_cells=4, variants=2,
                                 controllers=ctrls)
    verdicts = {c: {"robustness": {"label": "undecided", "text": "", "row": {}},
                    "safety": {"label": "safe", "text": "", "findings": []}} for c in ctrls}
    verdicts["HRVO"]["safety"] = {"label": "unsafe", "text": "collides", "findings": [
        "wall and obstacle contacts in 22.5%"]}
    table, per_pop = compare_table(runs, peds, ctrls, verdicts)
    cards = {c: tmp_path / EVALUATE_DIR / f"c{i}" / "card.html" for i, c in enumerate(ctrls)}
    study = study_from_dict(STUDY)
    paths = write_comparison(Comparison(ctrls, table, per_pop, cards, verdicts, study, tmp_path),
                             tmp_path / "compare" / "compare.html")
    dom, problems = load(paths["html"], COMPARE_PROBE, tmp_path / "profile")
    assert problems == []
    assert dom["scripts"] == 0 and dom["rows"] == 1 + len(ctrls)
    assert len(dom["images"]) == 1 and dom["images"][0]["ok"]
    assert dom["images"][0]["shown"] > 600
    assert "&lt;b&gt;odd &amp; name&lt;/b&gt;" in paths["html"].read_text()


def test_the_card_loads_and_shows_its_safety_table(tmp_path):
    """A robustness card (synthetic runs, a robot that collides with pedestrians) in the
    browser: no console error, its figure shows, the safety table has its rows and the
    unsafe finding is on the page."""
    import numpy as np

    from popnavshift.evaluate.card import card_tables
    from popnavshift.evaluate.card_page import write_card
    from popnavshift.evaluate.robustness import robustness_tables
    from popnavshift.outputs import FileSet
    from synth_study import no_effect, synthetic_study

    runs, peds = synthetic_study({"p1": no_effect, "p2": no_effect}, n_cells=6, variants=3)
    hit = runs.index[(runs["controller"] == "a")][::3]
    runs.loc[hit, "outcome"] = "pedestrian_collision"
    rob = robustness_tables(runs, peds, "a", ("b", "c"), {}, ["p1", "p2"], n_boot=50)
    card = card_tables(runs, peds, "a", ("b", "c"), rob, rng=np.random.default_rng(0),
                       n_boot=50)
    meta = {"study": "synthetic", "part": "main", "check": "skipped", "reused": 0,
            "executed": 0, "n_runs": 36, "n_errors": 0, "n_cells": 6, "n_populations": 2,
            "backends": "orca", "mappings": "A", "replay_note": "", "n_boot": 50, "seed": 0,
            "base_folder": "-", "seed_sets": 1, "n_used": len(runs), "safety_threshold": None,
            "parts": "main", "n_every": len(runs), "version": "0", "config_hash": "h",
            "made": "today"}
    with FileSet(tmp_path, "card.json") as files:
        html, _ = write_card(card, meta, files, None)
        files.commit({})
    dom, problems = load(html, COMPARE_PROBE, tmp_path / "profile")
    assert problems == []
    assert dom["scripts"] == 0 and dom["rows"] > 10
    assert dom["images"] and all(i["ok"] and i["shown"] > 600 for i in dom["images"])
    text = html.read_text()
    assert "Safety: unsafe" in text and "pedestrian collisions (robot moving)" in text
