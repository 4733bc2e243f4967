"""Every stage table's columns, dtypes and keys, declared once.

``check_table(df, stage)`` validates a table against its declaration and raises
:class:`InputError` naming the stage, the column and what was expected. Stages
and tests call it on what they produce and what they read.
The ``personas`` table's columns are the persona fields, so it is declared beside
them (:mod:`popnavshift.personas.table`): this layer imports no stage package.
"""

from __future__ import annotations

from .table_spec import DTYPES, SPECS, Column, TableSpec, check_table, declare  # noqa: F401
from .table_spec import column as _col

PARAMS: tuple[str, ...] = (
    "speed_mps",
    "clearance_m",
    "avoidance_gain",
    "yield_fraction",
    "reaction_delay_s",
    "detour_distance_m",
    "gap_acceptance",
)
"""The seven motion parameters θ = (v, d, a, y, τ, L, g) as column names, in this order."""
#: the normalised score column of each parameter (θ = low + z (high − low))
Z_COLUMNS: dict[str, str] = {
    "speed_mps": "z_speed",
    "clearance_m": "z_clearance",
    "avoidance_gain": "z_avoidance_gain",
    "yield_fraction": "z_yield_fraction",
    "reaction_delay_s": "z_reaction_delay",
    "detour_distance_m": "z_detour_distance",
    "gap_acceptance": "z_gap_acceptance",
}

PARAM_RANGES: dict[str, tuple[float, float]] = {
    "speed_mps": (0.60, 1.80),  # preferred speed [m/s]
    "clearance_m": (0.30, 1.20),  # robot clearance [m]
    "avoidance_gain": (0.60, 2.20),  # avoidance strength [-]
    "yield_fraction": (0.0, 1.0),  # yielding propensity [-]
    "reaction_delay_s": (0.15, 1.20),  # reaction delay [s]
    "detour_distance_m": (1.0, 4.0),  # detour threshold [m]
    "gap_acceptance": (0.0, 1.0),  # gap acceptance [-]
}
#: unit and meaning of each motion parameter (docs/method.md, response layer)
PARAM_DOCS: dict[str, tuple[str, str]] = {
    "speed_mps": ("m/s", "v: preferred walking speed"),
    "clearance_m": ("m", "d: clearance wanted from the robot, added to both radii in the "
                    "conflict test"),
    "avoidance_gain": ("1", "a: avoidance strength, a detour's lateral offset per m of "
                       "effective clearance"),
    "yield_fraction": ("1", "y: yielding propensity, fraction of the preferred speed given "
                       "up in a conflict"),
    "reaction_delay_s": ("s", "τ: reaction delay after the robot comes within 6 m"),
    "detour_distance_m": ("m", "L: robot distance at which yielding is complete and detours start"),
    "gap_acceptance": ("1", "g: gap acceptance, shrinks the effective clearance to d (1 − 0.35 g)"),
}

#: Ordered five-level response block (SPEC §3), encoded 0, .25, .5, .75, 1.
BLOCK_ITEMS: tuple[str, ...] = (
    "clearance",
    "waiting",
    "yielding",
    "gap",
    "detour",
    "trust",
    "urgency",
)
#: response-table columns: one action per probe, one level value per block item
ACTION_COLUMNS: tuple[str, ...] = tuple(f"action_{i}" for i in range(1, 9))
Q_COLUMNS: tuple[str, ...] = tuple(f"q_{k}" for k in BLOCK_ITEMS)
ACTIONS: tuple[str, ...] = ("continue", "slow", "stop", "yield", "pass", "detour")
VARIANTS: tuple[str, ...] = ("baseline", "deadline")

PERSONA_REF = "personas.persona_id"
MAPPING_DOC = (
    "profile set: a mapping A–D, or a robustness set of Mapping A (A~reassign, A~shuffle, "
    "A~block-<block>, A~<respondent>-2)"
)


_VARIANT = _col("variant", "str", "persona variant asked: baseline, or deadline (time "
                "pressure set to Deadline, the matched intervention)")
_SAMPLE = _col("sample", "int", "independent sample of the same question, from 0 (a study's "
               "`samples: k` asks each persona k times, each with its own seed; profiles "
               "read the per-item median across samples)")
_NOT_TOLD = "the respondent or server does not say (rule respondent, a server that omits it)"
#: what the server said of the model that answered (docs/llm.md, "The served model's
#: identity"): file name only, never a path
_IDENTITY = (
    _col("system_fingerprint", "str", "the server's build fingerprint of the reply (OpenAI "
         "system_fingerprint; llama.cpp's build)", nullable=True, missing=_NOT_TOLD),
    _col("model_file", "str", "file name of the served model (llama.cpp /props model_path, "
         "its name only)", nullable=True, missing=_NOT_TOLD),
    _col("model_quant", "str", "quantisation of the served model, the tag of its GGUF file "
         "name (e.g. Q4_K_M, Q8_0, F16)", nullable=True,
         missing="not told, or the file name carries no quantisation tag"),
    _col("model_size", "float", "size of the served model's file (llama.cpp /v1/models meta)",
         "B", nullable=True, missing=_NOT_TOLD),
    _col("model_params", "float", "parameters of the served model (llama.cpp /v1/models meta)",
         "1", nullable=True, missing=_NOT_TOLD),
    _col("server_build", "str", "the server's build (llama.cpp /props build_info)",
         nullable=True, missing=_NOT_TOLD),
    _col("model_sha256", "str", "sha256 of the model file, as the user gave it "
         "(respondent option model_sha256)", nullable=True, missing="not given"),
    _col("model_canaries", "str", "behavioural fingerprint of the served model: sha256 of "
         "its answers to the fixed canary prompts at temperature 0 (docs/llm.md)",
         nullable=True, missing="not measured (fingerprint off, a server that could not "
         "be asked, or one that answers the canaries differently each time)"),
)
#: the identity columns a respondent fills from what its server says of the model, once
#: per run (:func:`popnavshift.responses.collect.served_details`)
IDENTITY_COLUMNS: tuple[str, ...] = ("model_file", "model_quant", "model_size", "model_params",
                                     "server_build", "model_sha256", "model_canaries")
RESPONSES = declare(
    "responses",
    (
        _col("persona_id", "str", "the persona answering", refers=PERSONA_REF),
        _VARIANT,
        _SAMPLE,
        _col("respondent", "str", "respondent name (rule, openai, gemini, a plug-in)"),
        _col("model", "str", "the model asked for, with the respondent's settings"),
        _col("served_model", "str", "the model that answered, as the server named it",
             nullable=True, missing="the respondent or server names no model (rule "
             "respondent, a server that omits it)"),
        *_IDENTITY,
        _col("probe_set", "str", "hash of the probe texts and attributes asked"),
        *(_col(c, "str", f"action chosen in probe P{c[7:]}: one of {', '.join(ACTIONS)}")
          for c in ACTION_COLUMNS),
        *(_col(c, "float", f"self-rating '{c[2:]}': very_low … very_high as 0, .25, .5, .75, 1",
               "1") for c in Q_COLUMNS),
    ),
    ("persona_id", "variant", "sample"),
    doc="one valid answer of a respondent to the 8 probes and the 7-item block",
)

RESPONSES_INVALID = declare(
    "responses_invalid",
    (
        _col("persona_id", "str", "the persona asked", refers=PERSONA_REF),
        _VARIANT,
        _SAMPLE,
        _col("error", "str", "why the answer stayed invalid after the re-asks"),
        _col("raw", "str", "the respondent's last raw reply", nullable=True,
             missing="no reply was received (transport failure)"),
    ),
    ("persona_id", "variant", "sample"),
    doc="one record whose answer stayed invalid (listed, never dropped silently)",
)


def _param_columns(prefix: str = "", nullable: bool = False, **kw: str) -> tuple[Column, ...]:
    return tuple(
        Column(prefix + p, "float", nullable, unit=unit, doc=doc, **kw)
        for p, (unit, doc) in PARAM_DOCS.items()
    )


def _z_columns() -> tuple[Column, ...]:
    return tuple(
        Column(Z_COLUMNS[p], "float", unit="1",
               doc=f"normalised score of {p} in [0, 1]: {p} = low + z (high − low), "
               f"range {PARAM_RANGES[p][0]:g}–{PARAM_RANGES[p][1]:g} {PARAM_DOCS[p][0]}")
        for p in PARAMS
    )


PROFILES = declare(
    "profiles",
    (
        _col("persona_id", "str", "the persona profiled", refers=PERSONA_REF),
        _VARIANT,
        _col("mapping", "str", MAPPING_DOC),
        *_param_columns(),
        *_z_columns(),
        _col("caution", "float", "caution index from the responses, in [0, 1]", "1"),
    ),
    ("persona_id", "variant", "mapping"),
    doc="one persona's motion parameters θ under one profile set",
)

POPULATIONS = declare(
    "populations",
    (
        _col("population", "str", "population condition (homogeneous, mixed, "
             "high_time_pressure, …, matched_base, matched_deadline, split halves, nulls)"),
        _col("member", "int", "member index within the population, from 0"),
        _col("persona_id", "str", "the member's persona; 'median' for the homogeneous "
             "population's single median profile", refers=PERSONA_REF),
        _VARIANT,
        _col("mapping", "str", MAPPING_DOC),
        *_param_columns(),
    ),
    ("population", "mapping", "member"),
    doc="one member of a population condition with its motion parameters",
)

#: an episode's cell and size, in the episodes table and repeated in every run row
_CELL_COLUMNS = (
    _col("width", "float", "walkable width", "m"),
    _col("density", "float", "pedestrian density", "1/m²"),
    _col("robot_speed", "float", "robot's maximum speed", "m/s"),
    _col("variant", "int", "episode variant of the cell (1–3)"),
    _col("n_peds", "int", "number of pedestrians"),
)

EPISODES = declare(
    "episodes",
    (
        _col("id", "str", "episode id <scene>-w<width>-d<density>-s<robot_speed>-v<variant>"),
        _col("scene", "str", "sidewalk, head_on, crossing, bottleneck or obstruction"),
        *_CELL_COLUMNS,
        _col("seed", "int", "the episode's random seed (derived from the study seed)"),
    ),
    ("id",),
    doc="one episode of the study seed's 104-cell grid",
)

RUN_KEY: tuple[str, ...] = ("episode", "population", "controller", "backend", "mapping")
NO_ROBOT = "none"
"""The ``controller`` value of a no-robot baseline run."""
NO_ROBOT_LABEL = "no robot"
"""How a page names :data:`NO_ROBOT`."""
#: how a run's profile set was made, as columns (values:
#: :meth:`popnavshift.populations.perturb.ProfileSet.columns`)
PROFILE_SET_COLUMNS: tuple[str, ...] = (
    "profile_set", "profile_base", "perturbation", "perturbation_arg")
#: what a run's population is, as columns (values: PopulationSpec.columns of the study's index)
POPULATION_COLUMNS: tuple[str, ...] = ("population_role", "null_replicate")

_NO_ROBOT_NAN = "no robot (controller none), or the controller raised (controller_error)"
_RUN_COLUMNS = (
    _col("part", "str", "the first study part that plans the run; a run several parts "
         "share is stored once: select a part's runs with popnavshift.load(study, part)"),
    _col("episode", "str", "episode id; …@s<k> = the same cell and variant drawn with seed "
         "set k", refers="episodes.id"),
    _col("population", "str", "population condition", refers="populations.population"),
    _col("population_role", "str", "what the population is: observed (a condition of the "
         "study), a null design's role such as swap_null or sized_null (a null replicate: keep "
         "them out of any summary of the conditions), half (a split half of the noise floor)"),
    _col("null_replicate", "int", "the replicate k of a null population (swap_null, "
         "sized_null, …); 0 for the others"),
    _col("controller", "str", "robot controller id; none = no-robot baseline run"),
    _col("backend", "str", "pedestrian dynamics: orca (Ped-ORCA) or hl (navground HL)"),
    _col("mapping", "str", MAPPING_DOC, refers="populations.mapping"),
    _col("run_id", "str", "the run's id, a hash of the five key columns: joins runs and "
         "pedestrians"),
    _col("seed_set", "int", "study seed the episode was drawn with: the study's own, or k "
         "for an episode id …@s<k>"),
    _col("profile_set", "str", "how the profile set was made: original (a mapping A–D of "
         "the answers), reassign, shuffle, block-<block>, second_respondent"),
    _col("profile_base", "str", "the mapping (A–D) the profile set's profiles come from"),
    _col("perturbation", "str", "how the profile set departs from profile_base: none, "
         "reassign (whole profiles moved among persona ids), shuffle (each parameter "
         "column permuted within a population), block (only one response block varies), "
         "second_respondent (the matched pair answered by a second respondent)"),
    _col("perturbation_arg", "str", "the perturbation's argument: the block (time_pressure, "
         "caution, trust) or the second respondent's name; empty for none, reassign and "
         "shuffle"),
)

#: the robot's metrics: columns of ``runs`` that :func:`popnavshift.sim.metrics.robot_metrics`
#: computes, in its order (adding a metric: declare it here, compute it there)
ROBOT_METRICS: tuple[Column, ...] = (
    _col("robot_time", "float", "success time, else the 45 s limit", "s", nullable=True,
         missing="no robot (controller none)"),
    _col("outcome_time", "float", "time of the outcome", "s", nullable=True,
         missing=_NO_ROBOT_NAN),
    _col("robot_path_length", "float", "robot path length until the outcome", "m",
         nullable=True, missing=_NO_ROBOT_NAN),
    _col("robot_stop_time", "float", "time the robot moved slower than 0.05 m/s before "
         "the outcome", "s", nullable=True, missing=_NO_ROBOT_NAN),
    _col("robot_min_clearance", "float", "smallest robot–pedestrian distance minus radii "
         "before the outcome", "m", nullable=True, missing=_NO_ROBOT_NAN),
    _col("ped_collisions", "int", "robot–pedestrian contact events over the run"),
    _col("world_collisions", "int", "robot–wall/obstacle contact events over the run"),
    _col("contact_speed", "float", "the robot's speed at the contact that ended its run "
         "(near 0: something walked into a standing robot)", "m/s", nullable=True,
         missing="no collision ended the run (or no robot)"),
)
#: each pedestrian's metrics: columns of ``pedestrians`` that
#: :func:`popnavshift.sim.metrics.pedestrian_metrics` computes, in its order
PEDESTRIAN_METRICS: tuple[Column, ...] = (
    _col("arrived", "bool", "reached its exit before the 45 s limit"),
    _col("travel_time", "float", "time from t = 0 to crossing the exit line", "s",
         nullable=True, missing="never arrived"),
    _col("walk_distance", "float", "path length up to the exit (or the end of the run)",
         "m"),
    _col("stop_time", "float", "time slower than 0.05 m/s before leaving", "s"),
    _col("detour", "float", "walked minus the straight line from start to exit point",
         "m", nullable=True, missing="never arrived"),
    _col("min_robot_clearance", "float", "smallest distance to the robot minus both "
         "radii", "m", nullable=True, missing="no robot in the run"),
)

RUNS = declare(
    "runs",
    (
        *_RUN_COLUMNS,
        _col("run_inputs", "str", "16 hex digits hashing everything the run was simulated "
             "from: its episode draw, the profiles and persona ids in its slots, its backend "
             "and the code it ran (simulator, navground, controller). Equal in two runs: the "
             "same simulation; a later `run` carries every stored run whose inputs it still "
             "plans"),
        _col("scene", "str", "scene of the episode"),
        *_CELL_COLUMNS,
        _col("outcome", "str", "the robot's first event: success, pedestrian_collision, "
             "world_collision, timeout, controller_error; none without a robot"),
        *ROBOT_METRICS,
        _col("peds_arrived", "int", "pedestrians that reached their exit"),
        _col("steps", "int", "simulation steps of 0.1 s"),
        _col("error", "str", "what the controller raised", nullable=True,
             missing="the controller did not raise (every outcome but controller_error)"),
    ),
    RUN_KEY,
    doc="one simulated run: an episode × population × controller × backend × profile set",
)

PEDESTRIANS = declare(
    "pedestrians",
    (
        *_RUN_COLUMNS,
        _col("slot", "int", "pedestrian index in the episode, from 0"),
        _col("persona_id", "str", "the population member walking in this slot",
             refers=PERSONA_REF),
        *PEDESTRIAN_METRICS,
        *_param_columns(),
    ),
    (*RUN_KEY, "slot"),
    doc="one pedestrian of one run with its motion parameters and outcomes",
)
