"""A user's own task, defined in one file outside the package (examples/aggregation_task.py):
registered through the public registry, held to the conformance suite on the numpy,
cut-off and compiled torch cores (the C step refuses it with a reason), passing the
Gymnasium and PettingZoo API checkers, and trained with swarm-train and evaluated with
swarm-eval. Also: a task's own statistics, reward weights by term name, the registry's
and the plugin loader's refusals."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from conformance import VARIANTS, Variant, check, configs, observation_features
from gymnasium.utils.env_checker import check_env as gym_check_env
from hypothesis import HealthCheck, given, settings
from pettingzoo.test import parallel_api_test

from swarm_envs import metrics
from swarm_envs.config import RewardWeights, SwarmConfig, config_from_mapping, load_swarm_config
from swarm_envs.envs import backends
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.envs.task import REWARD_TERMS, STAT_KEYS, RewardTerm, Statistic, stat_keys
from swarm_envs.plugins import PLUGINS_ENV, load_plugin
from swarm_envs.tasks import TASKS, TaskSpec, register_task, task_config, task_names
from swarm_envs.tasks import unregister_task as drop_task

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "aggregation_task.py"

SETTINGS = settings(
    max_examples=int(os.environ.get("SWARM_ENVS_CONFORMANCE_EXAMPLES", "25")) // 2 or 1,
    deadline=None,
    derandomize=not os.environ.get("SWARM_ENVS_EXPLORE"),
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


@pytest.fixture(scope="module", autouse=True)
def aggregation():
    """The example's module, loaded as a user loads it (the environment variable that
    hands it to worker processes restored afterwards)."""
    before = os.environ.get(PLUGINS_ENV)
    module = load_plugin(EXAMPLE)
    yield module
    if before is None:
        os.environ.pop(PLUGINS_ENV, None)
    else:
        os.environ[PLUGINS_ENV] = before


# ---------------------------------------------------------------------------- registry


def test_the_example_registers_its_task_beside_the_package_s(aggregation):
    assert "aggregation" in task_names() and TASKS == ("navigation", "informed", "mill")
    cfg = task_config("aggregation")
    assert cfg.task_spec is aggregation.AGGREGATION
    assert cfg.reward.terms == {"contraction": 10.0} and cfg.reward.progress == 0.0
    assert load_plugin(EXAMPLE) is aggregation  # imported once
    assert gym.make("examples/SwarmAggregation-v0").unwrapped.cfg.task == "aggregation"
    assert aggregation.parallel_env(n_agents=4).cfg.task == "aggregation"


def test_no_time_to_goal_bound_for_a_task_with_its_own_success_rule(aggregation):
    from train.evaluate.bound import bound_reason

    assert bound_reason(task_config("navigation")) is None
    reason = bound_reason(task_config("aggregation"))
    assert reason is not None and "'aggregation'" in reason


def test_reward_weights_are_set_by_term_name_and_checked_against_the_task():
    cfg = load_swarm_config(None, {"task": "aggregation", "reward": {"contraction": 0.5}})
    assert cfg.reward.weight("contraction") == 0.5 and cfg.reward.success == 5.0
    assert config_from_mapping(SwarmConfig, {"task": "aggregation", **_zeroed()}).reward
    with pytest.raises(ValueError, match=r"unknown config key 'reward.spread'.*contraction"):
        task_config("aggregation", reward={"spread": 1.0})
    with pytest.raises(ValueError, match=r"reward.progress = 2.0 weighs no term"):
        task_config("aggregation", reward={"progress": 2.0})
    with pytest.raises(ValueError, match=r"unknown config key 'reward.contraction'"):
        task_config("navigation", reward={"contraction": 1.0})
    with pytest.raises(ValueError, match=r"terms.contraction must be"):
        RewardWeights(terms={"contraction": -1.0})


def _zeroed() -> dict:
    """A reward section with the shipped terms aggregation lacks at 0."""
    return {"reward": {"progress": 0, "arrival": 0, "mill": 0, "contraction": 1.0}}


def test_the_reward_adds_the_task_s_own_terms_by_their_weights():
    # The same episode with contraction weighted 0 and 2: the rewards differ by twice
    # the term, the shared definitions evaluated on each step's statistics.
    rewards, stats = [], []
    for w in (0.0, 2.0):
        core = SwarmNavCore(task_config("aggregation", reward={"contraction": w}), batch=3)
        core.reset(np.random.default_rng(0))
        start = core.stats()["expanse"]
        r, *_, s = core.step(np.full((3, 8, 2), 0.3))
        rewards.append(r)
        stats.append(s)
    np.testing.assert_allclose(rewards[1] - rewards[0], 2 * (start - stats[0]["expanse"]) / start)


def test_the_registry_refuses_clashes_naming_them():
    spec = TaskSpec("clash", "x", reward_terms=REWARD_TERMS[:1])
    with pytest.raises(ValueError, match="one of the package's"):
        register_task(dataclasses.replace(spec, name="mill"), replace=True)
    other = RewardTerm("progress", 1.0, "another progress", lambda r: 0.0 * r.effort)
    with pytest.raises(ValueError, match="'progress' is the package's term's name"):
        register_task(dataclasses.replace(spec, reward_terms=(other,)))
    stat = Statistic("expanse", "again", lambda f, task, xp: f.energy)
    with pytest.raises(ValueError, match="common statistics' names"):
        register_task(dataclasses.replace(spec, statistics=(stat,)))
    register_task(spec)
    try:
        register_task(spec)  # the same object again: nothing
        with pytest.raises(ValueError, match="registered already"):
            register_task(dataclasses.replace(spec, doc="y"))
        assert register_task(dataclasses.replace(spec, doc="y"), replace=True).doc == "y"
    finally:
        drop_task("clash")
    assert "clash" not in task_names()
    with pytest.raises(ValueError, match="task must be one of"):
        SwarmConfig(task="clash")


def test_the_env_docstring_lists_the_registered_terms_statistics_and_ends():
    from swarm_envs.envs.adapters.swarm_nav import SwarmNavEnv, SwarmNavParallelEnv
    from swarm_envs.envs.task import STATISTICS
    from swarm_envs.tasks import task_spec

    for doc in (SwarmNavEnv.__doc__, SwarmNavParallelEnv.__doc__):
        for spec in map(task_spec, TASKS):
            for term in spec.reward_terms:
                assert f"| ``{term.name}`` | {'+' if term.sign > 0 else '−'} | {term.doc} |" in doc
            assert f"- ``{spec.name}``: " in doc
        for stat in STATISTICS:
            assert f"- ``{stat.name}``: {stat.doc}" in doc
        assert "{rewards}" not in doc and "w_progress" not in doc


# ---------------------------------------------------------------------------- conformance


@pytest.mark.parametrize(
    "variant", [v for v in VARIANTS if v.backend != "native"], ids=lambda v: v.name
)
@SETTINGS
@given(cfg=configs(tasks=("aggregation",)))
def test_the_user_task_matches_the_reference_on_every_core_that_runs_it(variant, cfg):
    # As the suite's own property: a match, or a refusal with a reason (the torch core
    # runs the Euler integrator only); the example's config below runs on each.
    problems = check(variant, cfg)
    if problems and problems[0].startswith("refused: "):
        assert len(problems) == 1 and "aggregation" not in problems[0]
        return
    assert not problems, f"{variant.name} on {cfg}: {problems}"


@pytest.mark.parametrize("variant", [Variant("torch", np.float64), Variant("cutoff", np.float64)])
def test_the_example_s_own_config_conforms(variant):
    cfg = task_config("aggregation", n_agents=8)
    assert check(variant, cfg) == []
    assert "centroid_offset.1" in observation_features(cfg)


def test_the_c_step_refuses_the_user_task_and_the_env_falls_back_with_a_warning(monkeypatch):
    cfg = task_config("aggregation", backend="native")
    reason = backends.unsupported(cfg, "native")
    assert reason and ("centroid_offset" in reason or "unavailable" in reason or "off" in reason)
    monkeypatch.setattr(backends, "_WARNED", set())
    with pytest.warns(UserWarning, match="backend 'native' cannot run this config"):
        env = gym.make("examples/SwarmAggregation-v0", backend="native")
    assert env.unwrapped.core.backend != "native"


SPREAD = Statistic(
    "spread_max",
    "largest distance of a member from the members' centroid",
    lambda f, task, xp: xp.amax(xp.norm(f.x - xp.mean_agents(f.x)[:, None, :]), axis=-1),
)


@pytest.fixture
def own_statistics_task():
    spec = register_task(
        TaskSpec(
            "spread_task",
            "keep the farthest member close",
            reward_terms=(
                RewardTerm(
                    "spread_cut",
                    1.0,
                    "reduction of spread_max",
                    lambda r: r.prev["spread_max"] - r.stats["spread_max"],
                    weight=1.0,
                ),
            ),
            statistics=(SPREAD,),
            success=lambda f, task, xp: xp.astype(metrics.expanse(f.x, f.members) < 0.5, f.energy),
        )
    )
    yield spec
    drop_task(spec.name)


def test_a_task_s_own_statistics_reach_info_and_the_reward(own_statistics_task):
    cfg = task_config("spread_task", n_agents=6)
    assert stat_keys(cfg) == (*STAT_KEYS, "spread_max")
    for variant in (Variant("numpy", np.float32), Variant("cutoff", np.float64)):
        assert check(variant, cfg) == []
    for backend in ("torch", "native"):
        reason = backends.unsupported(cfg, backend)
        assert reason and reason.strip()
    core = SwarmNavCore(cfg, batch=2)
    core.reset(np.random.default_rng(1))
    before = core.stats()["spread_max"]
    r, *_, stats = core.step(np.zeros((2, 6, 2)))
    np.testing.assert_allclose(r, before - stats["spread_max"])


# ---------------------------------------------------------------------------- API checkers


def test_gymnasium_and_pettingzoo_checkers_pass_on_the_user_task(aggregation):
    env = gym.make("examples/SwarmAggregation-v0", n_agents=4, max_steps=20)
    gym_check_env(env.unwrapped, skip_render_check=True)
    parallel_api_test(aggregation.parallel_env(n_agents=4, max_steps=20), num_cycles=30)


def test_the_vec_env_runs_the_user_task(aggregation):
    venv = aggregation.vec_env(3, n_agents=4, max_steps=5)
    venv.reset()
    ended = []
    for _ in range(5):
        _, rewards, dones, infos = venv.step(np.zeros((12, 2), np.float32))
        ended.append(dones.all())
    assert rewards.shape == (12,) and "expanse" in infos[0] and ended == [False] * 4 + [True]


# ---------------------------------------------------------------------------- plugins


def test_the_plugin_loader_names_what_it_could_not_load(tmp_path):
    with pytest.raises(ValueError, match=r"plugin file not found: .*missing\.py"):
        load_plugin(tmp_path / "missing.py")
    broken = tmp_path / "broken_task.py"
    broken.write_text("raise RuntimeError('no task here')\n")
    with pytest.raises(ValueError, match=rf"plugin {broken} failed to load: RuntimeError"):
        load_plugin(broken)
    with pytest.raises(ValueError, match="plugin module not found: no_such_plugin_module"):
        load_plugin("no_such_plugin_module")
    assert load_plugin("swarm_envs.envs.task.shipped").SHIPPED_TASKS[0].name == "navigation"


# ---------------------------------------------------------------------------- training


def test_swarm_train_trains_the_user_task_and_swarm_eval_evaluates_it(tmp_path, monkeypatch):
    from train import cli_eval, cli_train

    monkeypatch.chdir(tmp_path)
    out = tmp_path / "run"
    code = cli_train.main(
        [
            "--config",
            str(ROOT / "examples" / "aggregation_task.yaml"),
            "--out",
            str(out),
            "--no-progress",
            "total_timesteps=2048",
            "n_swarms=2",
            "hyperparams.n_steps=64",
            "hyperparams.batch_size=256",
            "hyperparams.n_epochs=1",
        ]
    )
    assert code == 0 and (out / "model.zip").is_file()
    saved = (out / "train_config.yaml").read_text()
    assert str(EXAMPLE) in saved  # the plugin, by its path, for --resume
    code = cli_eval.main(
        [
            "--plugin",
            str(EXAMPLE),
            "--config",
            str(out / "env_config.yaml"),
            "--policies",
            str(out / "model.zip"),
            "zero",
            "--episodes",
            "2",
            "--out",
            str(tmp_path / "eval"),
            "--no-gif",
            "--no-plots",
            "--no-progress",
        ]
    )
    assert code == 0 and (tmp_path / "eval" / "results.json").is_file()
