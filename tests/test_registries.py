"""Registries: every way of naming a controller (and backend, respondent), and every error."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from example_controller import EXAMPLE, USER_MODULE, install_example
from popnavshift.controller_ids import controller_id, parse_controller_id
from popnavshift.design.plan import Run
from popnavshift.design.study import study_from_dict
from popnavshift.engine.batches import Batch, batches
from popnavshift.engine.run_inputs import run_inputs
from popnavshift.engine.stamps import code_stamps
from popnavshift.engine.worker import Context, run_batch
from popnavshift.episodes import assign_slots, get_episode
from popnavshift.errors import ConfigError, UnknownNameError
from popnavshift.responses.respondent import RESPONDENTS
from popnavshift.sim.backends import BACKENDS
from popnavshift.sim.check import check_controller
from popnavshift.sim.controllers import CONTROLLERS
from popnavshift.sim.controllers.navground_type import BehaviorClass
from popnavshift.sim.run import ControllerError, failed_result, simulate
from popnavshift.tables import check_table

CLASS_SPEC = "slow_near_peds.controller:SlowNearPeds"
EPISODE = "head_on-w1.8-d0.06-s1.0-v1"

@pytest.fixture
def user_path(tmp_path, monkeypatch):
    """The example package and a user module on sys.path (spawned workers inherit it)."""
    (tmp_path / "user_ctrls.py").write_text(USER_MODULE)
    (tmp_path / "import_bomb.py").write_text("raise ZeroDivisionError('boom on import')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.syspath_prepend(str(EXAMPLE))
    monkeypatch.setattr(CONTROLLERS, "_entries", dict(CONTROLLERS._entries))  # undo registrations
    return tmp_path


def members(n: int = 40) -> pd.DataFrame:
    """A population of ``n`` personas with fixed profiles (varied speeds)."""
    rng = np.random.default_rng(0)
    return pd.DataFrame({"population": "mixed", "member": range(n), "variant": "baseline",
                         "mapping": "A", "persona_id": [f"p{i:03d}" for i in range(n)],
                         "speed_mps": rng.uniform(0.8, 1.4, n), "clearance_m": 0.6,
                         "avoidance_gain": 1.2, "yield_fraction": 0.5, "reaction_delay_s": 0.5,
                         "detour_distance_m": 2.0, "gap_acceptance": 0.5})


def slots(episode: str = EPISODE) -> tuple:
    spec = get_episode(episode, seed=0)
    return spec, assign_slots(spec, members())


# --------------------------------------------------------------- ways of naming a controller
def test_a_class_spec_is_wrapped_into_a_checked_controller(user_path):
    factory = CONTROLLERS.make(CLASS_SPEC)
    assert isinstance(factory, BehaviorClass) and factory.name == CLASS_SPEC
    check_controller(factory)
    assert factory.describe()["class"] == CLASS_SPEC
    spec, members = slots()
    result = simulate(spec, members, CLASS_SPEC)
    assert result.run["controller"] == CLASS_SPEC
    assert result.run["outcome"] == "success"


def test_an_entry_point_names_the_example_controller(user_path, monkeypatch):
    install_example(user_path / "site")
    monkeypatch.syspath_prepend(str(user_path / "site"))
    factory = CONTROLLERS.make("slow_near_peds")
    assert isinstance(factory, BehaviorClass) and factory.name == "slow_near_peds"
    assert "slow_near_peds" in CONTROLLERS.names()
    spec, members = slots()
    assert simulate(spec, members, "slow_near_peds").run["controller"] == "slow_near_peds"


def test_navground_types_and_builtins_take_parameters_in_their_id():
    ident = controller_id("HL", {"tau": 0.3, "eta": 0.4})
    assert ident == 'HL{"eta":0.4,"tau":0.3}' == controller_id("HL", {"eta": 0.4, "tau": 0.3})
    assert parse_controller_id(ident) == ("HL", {"eta": 0.4, "tau": 0.3})
    factory = CONTROLLERS.make(ident)
    assert factory.describe()["tau"] == 0.3
    assert factory.build(_kin(), 0.35, 1.0).tau == pytest.approx(0.3, abs=1e-6)  # float32
    assert CONTROLLERS.make("reactive", buffer=0.1).params["buffer"] == 0.1
    spec, members = slots()
    assert simulate(spec, members, ident).run["controller"] == ident
    assert controller_id("HL", {"tau": 0.3}) != controller_id("HL", {"tau": 0.31})


def test_class_parameters_are_navground_properties_read_back(user_path):
    factory = CONTROLLERS.make(CLASS_SPEC, slow_distance=3.0, safety_margin=0.1)
    behavior = factory.build(_kin(), 0.35, 0.8)
    assert behavior.get("slow_distance") == 3.0
    assert behavior.safety_margin == pytest.approx(0.1, abs=1e-6)  # navground stores float32
    with pytest.raises(ConfigError, match="has no parameter 'slow'.*allowed: .*slow_distance"):
        CONTROLLERS.make(CLASS_SPEC, slow=3.0)


def _kin():
    from navground import core

    return core.kinematics.TwoWheelsDifferentialDriveKinematics(max_speed=1.0, wheel_axis=0.5)


def test_a_study_file_names_controllers_with_parameters():
    study = study_from_dict({"name": "s", "parts": {"main": {"controllers": [
        "reactive", CLASS_SPEC, {"name": "HL", "params": {"tau": 0.3}}]}}})
    assert study.parts["main"].controllers == ("reactive", CLASS_SPEC, 'HL{"tau":0.3}')
    with pytest.raises(ConfigError, match=r"parts.main.controllers.*\{name: NAME"):
        study_from_dict({"name": "s", "parts": {"main": {"controllers": [{"nam": "HL"}]}}})


def test_a_misspelt_parameter_of_an_unhashable_factory_is_a_config_error():
    """The parameter check reads each factory's signature once (a cache); a factory
    the cache cannot hold is still checked, not called with the bad parameter."""
    from popnavshift.registry import call_checked

    class Factory:  # a callable instance that defines __eq__: unhashable
        def __eq__(self, other):
            return self is other

        def __call__(self, speed=1.0):
            return speed

    with pytest.raises(ConfigError, match="takes no parameter 'sped'.*did you mean 'speed'"):
        call_checked("controller", "mine", Factory(), {"sped": 2.0})
    assert call_checked("controller", "mine", Factory(), {"speed": 2.0}) == 2.0


def test_backends_and_respondents_by_class_spec():
    assert BACKENDS.make("popnavshift.sim.backends:HLBackend").name == "hl"
    spec, members = slots()
    run = simulate(spec, members, None, "popnavshift.sim.backends:HLBackend").run
    assert run["backend"] == "popnavshift.sim.backends:HLBackend"
    rule = RESPONDENTS.make("popnavshift.responses.rule:RuleRespondent", seed=3)
    assert rule.name == "rule"
    with pytest.raises(ConfigError, match="not a pedestrian backend"):
        BACKENDS.make("collections:OrderedDict")
    with pytest.raises(ConfigError, match="not a Respondent.*subclass"):
        RESPONDENTS.make("collections:OrderedDict")
    with pytest.raises(UnknownNameError, match="did you mean 'orca'"):
        BACKENDS.make("orka")


# -------------------------------------------------------------------------------- errors
@pytest.mark.parametrize("spec, message", [
    ("no_such_pkg_xyz.mod:Cls", r"cannot import no_such_pkg_xyz.mod: ModuleNotFoundError"),
    ("import_bomb:Cls", r"cannot import import_bomb: ZeroDivisionError: boom on import"),
    ("slow_near_peds.controller:SlowNearPed", r"no attribute 'SlowNearPed'.*'SlowNearPeds'"),
    ("user_ctrls:NotABehavior", r"class user_ctrls.NotABehavior, not a navground Behavior.*"
                                r"must subclass navground.core.Behavior"),
    ("math:pi", r"float 3.14.*not a navground Behavior"),
    ("user_ctrls:", r"not a Python object spec.*package.module:Class"),
    ('HL{"tau":', r"expected NAME or NAME\{JSON parameters\}"),
])
def test_bad_controller_specs_are_one_line_config_errors(user_path, spec, message):
    with pytest.raises(ConfigError, match=message):
        CONTROLLERS.make(spec)


def test_an_unknown_name_suggests_close_ones(user_path):
    with pytest.raises(UnknownNameError, match="did you mean 'robot_orca'"):
        CONTROLLERS.make("robot_orka")


def test_an_entry_point_that_fails_to_load_is_named(user_path, monkeypatch):
    info = install_example(user_path / "site")
    (info / "entry_points.txt").write_text(
        "[popnavshift.controllers]\nbroken_ctrl = import_bomb:Cls\n")
    monkeypatch.syspath_prepend(str(user_path / "site"))
    with pytest.raises(ConfigError, match="entry point 'broken_ctrl' .*failed to load"):
        CONTROLLERS.make("broken_ctrl")


def test_a_controller_that_raises_is_a_controller_error_with_the_time(user_path):
    spec, members = slots()
    with pytest.raises(ControllerError, match=r"'user_ctrls:RaisesNearPeds' raised "
                                              r"RuntimeError at t = \d+\.\d s: a pedestrian"):
        simulate(spec, members, "user_ctrls:RaisesNearPeds")


def test_our_own_bugs_are_not_blamed_on_the_controller(user_path, monkeypatch):
    from popnavshift.sim import pedestrians

    def broken(*args, **kwargs):
        raise KeyError("bug in the response layer")

    monkeypatch.setattr(pedestrians.ResponseLayer, "step", broken)
    spec, members = slots()
    with pytest.raises(KeyError, match="bug in the response layer"):
        simulate(spec, members, CLASS_SPEC)


def test_the_worker_records_a_controller_error_and_goes_on(user_path):
    runs = tuple(Run(EPISODE, "mixed", c, "orca", "A", "main")
                 for c in ("none", "user_ctrls:RaisesNearPeds", CLASS_SPEC))
    inputs = run_inputs(runs, members(), 0, code_stamps(r.controller for r in runs))
    (batch,) = batches(runs, inputs)
    _, table, peds, _ = run_batch(batch, Context(populations=members(), episode_seed=0, specs={}))
    out = table.set_index("controller")
    assert out.loc["user_ctrls:RaisesNearPeds", "outcome"] == "controller_error"
    assert "a pedestrian is too close" in out.loc["user_ctrls:RaisesNearPeds", "error"]
    assert out.loc["user_ctrls:RaisesNearPeds", "robot_time"] == 45.0
    assert out.loc[CLASS_SPEC, "outcome"] == "success" and out["error"].isna().sum() == 2
    assert set(peds["controller"]) == {"none", CLASS_SPEC}  # no rows for the failed run
    check_table(table, "runs")
    check_table(peds, "pedestrians")


def test_a_repeated_controller_error_is_recorded_for_each_run(user_path):
    """A run with the inputs of a failed one (a population with the same profiles)
    fails the same way, and its row says so with the same message."""
    twin = members().assign(population="twin")
    runs = tuple(Run(EPISODE, p, "user_ctrls:RaisesNearPeds", "orca", "A", "main")
                 for p in ("mixed", "twin"))
    _, table, peds, simulated = run_batch(Batch(EPISODE, "orca", "A", runs),
                                          Context(populations=pd.concat([members(), twin]),
                                                  episode_seed=0, specs={}))
    assert simulated == 1 and peds.empty
    assert list(table["outcome"]) == ["controller_error"] * 2
    assert table["error"].nunique() == 1 and "too close" in table["error"].iloc[0]
    assert list(table["population"]) == ["mixed", "twin"]


def test_a_failed_result_has_the_columns_and_dtypes_of_a_run():
    spec, members = slots()
    ok = simulate(spec, members, "robot_orca")
    failed = failed_result(spec, "robot_orca", "orca")
    assert list(failed.run) == list(ok.run)
    assert failed.pedestrians.empty
    pd.testing.assert_series_equal(failed.pedestrians.dtypes, ok.pedestrians.dtypes)


def test_the_contract_check_rejects_a_broken_controller_and_reports_one_that_raises(user_path):
    from popnavshift.evaluate.run import check

    with pytest.raises(ConfigError, match="infeasible command.*contract check"):
        check(CONTROLLERS.make("user_ctrls:Infeasible"))
    assert check(CONTROLLERS.make("user_ctrls:RaisesNearPeds")).startswith(
        "raised RuntimeError in the contract check")
    assert check(CONTROLLERS.make(CLASS_SPEC)) == "passed"



def test_a_respondent_that_declares_uses_cache_gets_the_study_cache(tmp_path, monkeypatch):
    """Caching follows the respondent's declared kind, not its name: a newly registered
    network respondent gets the folder's response cache, the rule respondent none."""
    from popnavshift.pipeline import RESPONSE_CACHE, respondent_from
    from popnavshift.responses.llm.openai import OpenAIRespondent

    class LocalModel(OpenAIRespondent):
        name = "local_model"

    monkeypatch.setattr(RESPONDENTS, "_entries", dict(RESPONDENTS._entries))
    RESPONDENTS.register("local_model", LocalModel)
    local = {"base_url": "http://127.0.0.1:9/v1", "api_key_env": None}
    made = respondent_from("local_model", local, tmp_path)
    assert isinstance(made, LocalModel) and made.cache_path == tmp_path / RESPONSE_CACHE
    other = tmp_path / "elsewhere.sqlite"
    assert respondent_from("local_model", {**local, "cache_path": other},
                           tmp_path).cache_path == other
    rule = respondent_from("rule", {}, tmp_path)
    assert not rule.uses_cache and not hasattr(rule, "cache_path")


def test_llm_settings_are_declared_once_and_taken_by_every_llm_respondent():
    """Every LLM respondent takes the settings of ``LLMSettings`` with their declared
    defaults (its signature lists them, so a mistyped one is named), and its own options."""
    import inspect

    from popnavshift.responses.llm.settings import SETTING_NAMES, LLMSettings

    for name, own in (("openai", {"base_url", "api_key_env", "extra_body"}),
                      ("gemini", {"base_url", "api_key_env"})):
        cls = RESPONDENTS.resolve(name)
        params = inspect.signature(cls).parameters
        assert set(params) == {"model", *own, *SETTING_NAMES}
        assert {n: params[n].default for n in SETTING_NAMES} == {
            n: getattr(LLMSettings, n) for n in SETTING_NAMES}
        made = RESPONDENTS.make(name, model="m", timeout=7.5, max_retries=0)
        assert (made.timeout, made.max_retries, made.deadline) == (7.5, 0, None)
    with pytest.raises(ConfigError, match="did you mean 'max_retries'"):
        RESPONDENTS.make("openai", max_retry=3)


def test_a_missing_required_parameter_is_named_not_a_traceback():
    from popnavshift.registry import call_checked

    def factory(tau: float, horizon: float = 5.0) -> None:
        return None

    with pytest.raises(ConfigError, match="'x' needs the parameter tau$"):
        call_checked("controller", "x", factory, {})
    with pytest.raises(ConfigError, match="takes no parameter 'k'; parameters: tau, horizon"):
        call_checked("controller", "x", factory, {"k": 1})
