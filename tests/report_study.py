"""The small study the report tests share (test_report.py, test_report_browser.py): run and
reported once a session, by the ``reported_study`` fixture of conftest.py."""

from __future__ import annotations

from pathlib import Path

#: Like the built-in quick study (pinned here so its edits cannot break these tests):
#: 4 populations with the matched pair, 10 episodes, narrow and wide, all 3 controllers.
STUDY = {
    "name": "report-test",
    "seed": 0,
    "personas": {"source": "synthetic", "n": 300},
    "matched_n": 60,
    "mappings": ["A"],
    "parts": {"main": {
        "populations": ["homogeneous", "mixed", "matched_base", "matched_deadline"],
        "episodes": {"scenes": ["sidewalk", "head_on", "bottleneck", "crossing", "obstruction"],
                     "widths": [1.8, 4.2], "densities": [0.06], "robot_speeds": [1.0],
                     "variants": [1]}}},
}
#: The report's bootstrap (test_report.py recomputes its intervals with the same seed and
#: resamples) and one replay per kind.
RNG_SEED, N_BOOT, REPLAYS = 0, 200, 1


def run_and_report(folder: Path) -> Path:
    """:data:`STUDY` run into ``folder`` and reported; ``folder``."""
    from popnavshift.design.study import study_from_dict
    from popnavshift.engine.runner import run_study
    from popnavshift.report import build_report

    run_study(study_from_dict(STUDY), folder, workers=1, show_progress=False)
    build_report(folder, rng_seed=RNG_SEED, n_boot=N_BOOT, replays=REPLAYS)
    return folder
