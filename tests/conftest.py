"""Shared fixtures. The network guard (pytest-socket, loopback only) is set in pyproject."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cli_helpers import cli, tiny_study
from popnavshift.personas.fields import PERSONA_FIELDS, vocabulary


@pytest.fixture
def random_personas():
    """A factory of persona tables with uniformly random field values (no correlations)."""

    def make(n: int = 200, seed: int = 0) -> pd.DataFrame:
        rng = np.random.default_rng(seed)
        df = pd.DataFrame(
            {
                f: [vocabulary(f)[i] for i in rng.integers(0, len(vocabulary(f)), n)]
                for f in PERSONA_FIELDS
            }
        )
        df.insert(0, "persona_id", [f"t-{i:05d}" for i in range(n)])
        df.insert(1, "source", "test")
        return df

    return make


@pytest.fixture(scope="session")
def finished(tmp_path_factory) -> Path:
    """A finished tiny study (2 runs), made once for every CLI module; tests copy it before
    damaging it."""
    root = tmp_path_factory.mktemp("finished")
    proc = cli("run", str(tiny_study(root)), "--out", str(root / "s"), "--no-report", "-w", "1")
    assert proc.returncode == 0, proc.stderr
    return root / "s"


@pytest.fixture(scope="session")
def reported_study(tmp_path_factory) -> Path:
    """The report tests' small study (report_study.py), run and reported once for the
    modules that read it; tests copy it before altering it."""
    from report_study import run_and_report

    return run_and_report(tmp_path_factory.mktemp("reported"))


@pytest.fixture(scope="session")
def carded(finished, tmp_path_factory) -> Path:
    """The finished tiny study with the robustness card of `reactive` (20 resamples),
    evaluated once; its study file is ``../tiny.yaml``. Tests copy it before changing it."""
    import shutil

    from popnavshift.design.study import load_study
    from popnavshift.engine.ownership import claim_folder
    from popnavshift.evaluate import evaluate, make_card

    root = tmp_path_factory.mktemp("carded")
    folder = root / "s"
    shutil.copytree(finished, folder)
    study = load_study(str(tiny_study(root)))
    claim_folder(folder, study, force=None)
    make_card(evaluate("reactive", study, folder, workers=1, show_progress=False), n_boot=20)
    return folder


@pytest.fixture(scope="session")
def reported_tiny(finished, tmp_path_factory) -> Path:
    """A copy of the finished tiny study with the report `popnavshift run` writes (and
    finds current); tests copy it before changing it."""
    from cli_helpers import study_copy
    from popnavshift.report.build import build_report, report_is_current

    folder = study_copy(finished, tmp_path_factory.mktemp("reported_tiny") / "s")
    run = {"rng_seed": 0, "n_boot": 1000, "replays": 2}
    build_report(folder, **run)
    assert report_is_current(folder, run) == ""
    return folder
