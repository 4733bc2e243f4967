"""The paper's reported figures (popnavshift.tex §V, SPEC §9) — THE PAPER'S, NOT OURS.

Declared here once: the report sets them beside our numbers and the findings check
the qualitative ones (tail ratio, directions of the matched change). Units follow our
tables: reversal rates as fractions in [0, 1]; outcome shares in %; times in s;
clearances in m. Our personas, respondent and formulas differ, so only the
qualitative pattern is compared; nothing is tuned to hit these.
"""

from __future__ import annotations

Rates = dict[str, float]  # metric → reversal rate

#: the paper's main grid: cells and populations (a smaller study's intervals are wider)
N_CELLS, N_POPULATIONS = 104, 8

#: Table I: comparison (matched, all_pairs) → cells (all, completed) → metric → rate
REVERSAL_RATE: dict[str, dict[str, Rates]] = {
    "matched": {"all": {"robot_time": 0.086, "mean_delay": 0.224, "worst_decile": 0.239}},
    "all_pairs": {
        "all": {"robot_time": 0.087, "mean_delay": 0.258, "worst_decile": 0.248},
        "completed": {"robot_time": 0.050, "mean_delay": 0.215, "worst_decile": 0.221},
    },
}

_OUTCOME_COLUMNS = ("success_pct", "pedestrian_collision_pct", "world_collision_pct",
                    "timeout_pct", "robot_time", "min_clearance", "mean_delay", "worst_decile")
#: Table II: controller → column of :func:`popnavshift.analysis.summary.controller_outcomes`
CONTROLLER_OUTCOMES: dict[str, dict[str, float]] = {
    c: dict(zip(_OUTCOME_COLUMNS, v, strict=True))
    for c, v in {
        "reactive": (90.3, 2.6, 0.1, 7.0, 22.9, 0.70, 1.25, 5.13),
        "early_yield": (81.5, 5.4, 0.0, 13.0, 28.4, 0.70, 1.06, 4.42),
        "robot_orca": (87.8, 2.1, 7.1, 3.1, 24.2, 0.73, 0.65, 2.80),
    }.items()
}

#: Fig. 4: width [m] → pooled population sensitivity of mean delay [s]
WIDTH_SENSITIVITY: dict[float, float] = {1.8: 2.23, 4.2: 0.50}
#: worst-decile delay ≈ this × mean delay ("approximately four times")
TAIL_TO_MEAN_RATIO = 4.0
#: Fig. 2: sign of the matched deadline shift's change in mean delay per controller
MATCHED_CHANGE_SIGN: dict[str, int] = {"reactive": -1, "early_yield": 1, "robot_orca": -1}

# Robustness (§IV-C, §V-D, §V-E), keyed by the runs tables' profile-set columns
#: Table III: profile_base (mapping A–D) → rate
MAPPING_RATE: dict[str, Rates] = {
    "A": {"mean_delay": 0.245, "worst_decile": 0.260},
    "B": {"mean_delay": 0.242, "worst_decile": 0.286},
    "C": {"mean_delay": 0.246, "worst_decile": 0.257},
    "D": {"mean_delay": 0.375, "worst_decile": 0.358},
}
#: Table III: profile_base → share of controller orderings shared with Mapping A
MAPPING_AGREEMENT: dict[str, Rates] = {
    "B": {"mean_delay": 0.923, "worst_decile": 0.926},
    "C": {"mean_delay": 0.922, "worst_decile": 0.918},
    "D": {"mean_delay": 0.768, "worst_decile": 0.710},
}
#: §V-D, five shared populations: perturbation of Mapping A → rate
STRUCTURE_RATE: dict[str, Rates] = {
    "none": {"mean_delay": 0.284, "worst_decile": 0.269},
    "reassign": {"mean_delay": 0.198, "worst_decile": 0.188},
    "shuffle": {"mean_delay": 0.268, "worst_decile": 0.297},
}
#: §V-E, cells completed under both backends: backend → rate
BACKEND_RATE: dict[str, Rates] = {
    "orca": {"robot_time": 0.032, "mean_delay": 0.105, "worst_decile": 0.098},
    "hl": {"robot_time": 0.024, "mean_delay": 0.352, "worst_decile": 0.346},
}
#: the matched pair per respondent: perturbation (none = the first) → rate
RESPONDENT_RATE: dict[str, Rates] = {
    "none": REVERSAL_RATE["matched"]["all"],  # the first respondent: the matched headline
    "second_respondent": {"robot_time": 0.091, "mean_delay": 0.256, "worst_decile": 0.265},
}
