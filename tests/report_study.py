"""The small study the report tests run once (test_report.py, test_report_browser.py)."""

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
