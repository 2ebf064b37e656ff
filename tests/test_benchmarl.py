"""BenchMARL on the batched core (``train.benchmarl``, docs/ecosystem.md).

The TorchRL env passes TorchRL's ``check_env_specs`` for every task, steps exactly as
the SB3 ``vec_env`` over the same core does, resets only the swarms TorchRL asks for,
and ends episodes with the right flags; the BenchMARL task checks its config; a short
MAPPO experiment trains on SwarmNav (the long form is slow-marked).

``make install`` installs the ``benchmarl`` extra, so CI (``CI`` set) fails if it is
missing; elsewhere the module is skipped, saying what to install.
"""

from __future__ import annotations

import importlib.util
import os
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

HAVE_BENCHMARL = importlib.util.find_spec("benchmarl") is not None
if not HAVE_BENCHMARL and not os.environ.get("CI"):
    pytest.skip(
        'BenchMARL is not installed: pip install -e ".[benchmarl]" (make install does)',
        allow_module_level=True,
    )

import torch  # noqa: E402
from benchmarl.experiment.callback import Callback  # noqa: E402
from torchrl.envs.utils import check_env_specs  # noqa: E402

from swarm_envs import swarm_nav_v0  # noqa: E402
from swarm_envs.config import UnknownKeyError  # noqa: E402
from train.benchmarl import SwarmTask, SwarmTorchRLEnv  # noqa: E402

DOC = Path(__file__).resolve().parents[1] / "docs" / "ecosystem.md"

TASKS = {"SWARM_NAV": "navigation", "SWARM_INFORMED": "informed", "SWARM_MILL": "mill"}


@pytest.fixture
def one_torch_thread() -> Iterator[None]:
    """Training on one torch thread: two threads on a shared 2-core machine run the
    small networks several times slower."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


# --------------------------------------------------------------------------- the TorchRL env


@pytest.mark.parametrize("task", TASKS.values())
@pytest.mark.parametrize("return_state", [False, True])
def test_env_passes_torchrl_check_env_specs(task: str, return_state: bool):
    env = SwarmTorchRLEnv(3, task=task, n_agents=4, max_steps=6, return_state=return_state)
    check_env_specs(env, seed=0)
    assert env.batch_size == torch.Size([3])
    assert env.group_map == {"agents": [f"agent_{i}" for i in range(4)]}
    td = env.rollout(8, break_when_any_done=False)
    obs_dim = env.observation_spec["agents", "observation"].shape[-1]
    assert td["next", "agents", "observation"].shape == (3, 8, 4, obs_dim)
    assert td["agents", "action"].shape == (3, 8, 4, 2)
    assert td["next", "agents", "reward"].shape == (3, 8, 4, 1)
    assert td["next", "done"].shape == (3, 8, 1)
    assert ("next", "state") in td.keys(True) if return_state else "state" not in td.keys()
    if return_state:
        state = td["next", "state"]
        assert torch.equal(state, td["next", "agents", "observation"].reshape(3, 8, -1))


FAILING = {"failed_fraction": 0.4, "failure_mode": "removed", "failure_time": [1, 8]}


@pytest.mark.parametrize(
    "kwargs",
    [{}, {"task": "informed"}, {"perturbations": FAILING}],
    ids=["navigation", "informed", "removed agents"],
)
def test_env_steps_as_the_vec_env_over_the_same_core(kwargs: dict[str, Any]):
    """Same seed and actions: the same observations and rewards as the SB3 ``vec_env``
    (one core, float32), the swarm's reward given to each of its agents. Agents that
    stopped acting observe zeros in both; the ``vec_env`` gives their slots reward 0."""
    B, N, steps = 3, 5, 12
    env = SwarmTorchRLEnv(B, n_agents=N, max_steps=50, **kwargs)
    vec = swarm_nav_v0.vec_env(B, n_agents=N, max_steps=50, n_threads=1, **kwargs)
    assert env.backend == vec.backend
    env.set_seed(7)
    vec.seed(7)
    td = env.reset()
    obs = vec.reset()
    np.testing.assert_array_equal(td["agents", "observation"].numpy().reshape(B * N, -1), obs)
    rng = np.random.default_rng(0)
    stopped = 0
    for _ in range(steps):
        status = getattr(env.core, "status", None)
        acting = np.ones(B * N, bool) if status is None else (status == 0).reshape(-1)
        action = rng.uniform(-1, 1, (B, N, 2)).astype(np.float32)
        td["agents", "action"] = torch.from_numpy(action)
        td = env.step(td)["next"]
        obs, rewards, _, _ = vec.step(action.reshape(B * N, 2))
        assert not td["done"].any()
        np.testing.assert_array_equal(td["agents", "observation"].numpy().reshape(B * N, -1), obs)
        reward = td["agents", "reward"].numpy().reshape(-1)
        np.testing.assert_array_equal(reward[acting], rewards[acting])
        stopped += int((~acting).sum())
    assert stopped > 0 if "perturbations" in kwargs else stopped == 0
    vec.close()


def test_episode_flags_and_only_the_asked_swarms_reset():
    env = SwarmTorchRLEnv(4, n_agents=3, max_steps=5)
    env.set_seed(0)
    td = env.rollout(5, break_when_any_done=False)
    last = td[:, -1]["next"]
    assert last["truncated"].all() and last["done"].all() and not last["terminated"].any()
    assert not td[:, :-1]["next", "done"].any()
    before = env.core.x.copy()
    mask = torch.tensor([[True], [False], [True], [False]])
    env.reset(last.clone().set("_reset", mask))
    after = env.core.x
    np.testing.assert_array_equal(after[[1, 3]], before[[1, 3]])
    assert not np.array_equal(after[[0, 2]], before[[0, 2]])
    np.testing.assert_array_equal(env.core.t, [0, 5, 0, 5])


def test_a_seed_gives_the_same_rollout():
    def rollout(seed: int) -> torch.Tensor:
        env = SwarmTorchRLEnv(2, n_agents=3, max_steps=4)
        env.set_seed(seed)
        torch.manual_seed(seed)  # the random actions
        return env.rollout(10, break_when_any_done=False)["next", "agents", "observation"]

    assert torch.equal(rollout(3), rollout(3))
    assert not torch.equal(rollout(3), rollout(4))


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"n_swarms": 0}, ValueError, "n_swarms must be an integer >= 1"),
        ({"n_swarms": True}, ValueError, "n_swarms"),
        ({"return_state": "yes"}, ValueError, "return_state must be True or False"),
        ({"frameskip": 1}, UnknownKeyError, "unexpected keyword argument 'frameskip'"),
        ({"n_agents": 0}, ValueError, "n_agents"),
    ],
)
def test_env_refuses_bad_arguments(kwargs: dict[str, Any], error: type, match: str):
    with pytest.raises(error, match=match):
        SwarmTorchRLEnv(**{"n_swarms": 2, **kwargs})


def test_env_refuses_a_bad_action():
    env = SwarmTorchRLEnv(2, n_agents=3)
    td = env.reset()
    td["agents", "action"] = torch.full((2, 3, 2), float("nan"))
    with pytest.raises(ValueError, match=r"NaN|finite"):
        env.step(td)


# --------------------------------------------------------------------------- the BenchMARL task


@pytest.mark.parametrize(("member", "task"), TASKS.items())
def test_task_builds_its_env_with_its_defaults(member: str, task: str):
    bm_task = SwarmTask[member].get_task(config={"n_agents": 4, "return_state": True})
    assert bm_task.swarm_config.task == task
    env = bm_task.get_env_fun(num_envs=2, continuous_actions=True, seed=0, device="cpu")()
    assert env.cfg.task == task and env.batch_size == torch.Size([2])
    assert bm_task.max_steps(env) == env.cfg.max_steps
    assert bm_task.group_map(env) == env.group_map
    assert set(bm_task.state_spec(env).keys()) == {"state"}
    assert "state" not in bm_task.observation_spec(env).keys()
    assert bm_task.action_spec(env)["agents", "action"].shape == (4, 2)


def test_task_without_config_has_the_task_defaults():
    mill = SwarmTask.SWARM_MILL.get_task()
    assert mill.swarm_config == swarm_nav_v0.parallel_env(task="mill").cfg
    assert SwarmTask.SWARM_NAV.get_from_yaml().swarm_config == swarm_nav_v0.parallel_env().cfg


def test_task_reads_a_yaml_file(tmp_path: Path):
    path = tmp_path / "task.yaml"
    path.write_text("n_agents: 6\nmax_steps: 30\n")
    task = SwarmTask.SWARM_INFORMED.get_from_yaml(str(path))
    assert (task.swarm_config.n_agents, task.swarm_config.max_steps) == (6, 30)
    assert task.swarm_config.task == "informed"


def test_task_refuses_bad_configs():
    with pytest.raises(UnknownKeyError, match="unexpected keyword argument 'n_agent'"):
        SwarmTask.SWARM_NAV.get_task(config={"n_agent": 4})
    with pytest.raises(ValueError, match="must not set 'task'"):
        SwarmTask.SWARM_NAV.get_task(config={"task": "mill"})
    with pytest.raises(ValueError, match="continuous actions only"):
        SwarmTask.SWARM_NAV.get_task().get_env_fun(4, False, 0, "cpu")


# --------------------------------------------------------------------------- MAPPO


class EvaluationReturns(Callback):
    """A BenchMARL callback that keeps each evaluation's episode returns (per swarm)."""

    def __init__(self) -> None:
        super().__init__()
        self.returns: list[np.ndarray] = []
        self.lengths: list[list[int]] = []

    def on_evaluation_end(self, rollouts: list[Any]) -> None:
        # The swarm's reward is each agent's: agent 0's sums to the episode return.
        returns = [r["next", "agents", "reward"][:, 0, 0].sum().item() for r in rollouts]
        self.returns.append(np.array(returns))
        self.lengths.append([r.batch_size[0] for r in rollouts])


def run_experiment(
    save_folder: Path,
    frames: int,
    frames_per_batch: int,
    evaluations: int = 1,
    algorithm: str = "MappoConfig",
    task: str = "SWARM_NAV",
    task_config: dict[str, Any] | None = None,
) -> tuple[Any, Any]:
    """A BenchMARL experiment (MAPPO on SwarmNav, as docs/ecosystem.md gives it, unless
    told), evaluated at its start and every ``frames // evaluations`` frames (the
    marl-eval JSON is its only log); every parameter of the policy must have trained."""
    from benchmarl import algorithms
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig

    config = ExperimentConfig.get_from_yaml()
    config.loggers = []
    config.create_json = True  # BenchMARL evaluates only when something logs
    config.render = False
    config.save_folder = str(save_folder)
    config.checkpoint_at_end = False
    config.max_n_frames = frames
    config.on_policy_collected_frames_per_batch = frames_per_batch
    config.on_policy_n_envs_per_worker = 16  # swarms stepped at once
    config.on_policy_n_minibatch_iters = 4
    config.on_policy_minibatch_size = 400
    config.off_policy_collected_frames_per_batch = frames_per_batch
    config.off_policy_n_envs_per_worker = 16
    config.off_policy_n_optimizer_steps = 20
    config.off_policy_memory_size = 10 * frames_per_batch
    config.lr = 3e-4
    config.evaluation_interval = frames // evaluations
    config.evaluation_episodes = 8
    returns = EvaluationReturns()
    experiment = Experiment(
        task=SwarmTask[task].get_task(
            config={"n_agents": 4, "max_steps": 50, **(task_config or {})}
        ),
        algorithm_config=getattr(algorithms, algorithm).get_from_yaml(),
        model_config=MlpConfig.get_from_yaml(),
        critic_model_config=MlpConfig.get_from_yaml(),
        seed=0,
        config=config,
        callbacks=[returns],
    )
    start = [p.detach().clone() for p in experiment.policy.parameters()]
    experiment.run()
    params = experiment.policy.parameters()
    assert all(not torch.equal(a, b) for a, b in zip(start, params, strict=True))
    return experiment, returns


def test_mappo_experiment_on_swarm_nav(tmp_path: Path, one_torch_thread: None):
    experiment, returns = run_experiment(tmp_path, frames=1600, frames_per_batch=800)
    assert experiment.total_frames == 1600 and experiment.n_iters_performed == 2
    # Evaluated before training and at its end: 8 swarms at once, one episode each.
    assert len(returns.returns) == 2 and returns.lengths == [[50] * 8] * 2
    assert all(np.isfinite(r).all() and r.shape == (8,) for r in returns.returns)
    assert list(tmp_path.glob("mappo_swarm_nav*"))  # its folder, inside tmp_path


@pytest.mark.parametrize(
    ("algorithm", "task", "task_config"),
    [
        ("IppoConfig", "SWARM_INFORMED", {}),
        ("MasacConfig", "SWARM_MILL", {"return_state": True}),
    ],
)
def test_other_algorithms_and_tasks_run(
    tmp_path: Path, one_torch_thread: None, algorithm: str, task: str, task_config: dict
):
    experiment, returns = run_experiment(
        tmp_path, 1600, 800, algorithm=algorithm, task=task, task_config=task_config
    )
    assert experiment.total_frames == 1600 and len(returns.returns) == 2


@pytest.mark.slow
def test_mappo_learns_swarm_nav(tmp_path: Path, one_torch_thread: None):
    """The long form: MAPPO raises SwarmNav's evaluation return."""
    _, returns = run_experiment(tmp_path, frames=96_000, frames_per_batch=4_000, evaluations=4)
    first, last = returns.returns[0], returns.returns[-1]
    assert last.mean() > first.mean() + 2 * first.std() / np.sqrt(first.size), (first, last)


def test_docs_recipe_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, one_torch_thread: None):
    """docs/ecosystem.md's BenchMARL blocks (the MAPPO run and the env), in a temporary
    folder: the run writes its CSV logs and marl-eval JSON into the working folder."""
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.DOTALL)
    blocks = [b for b in blocks if "benchmarl" in b]
    assert len(blocks) == 2, f"expected the MAPPO recipe and the env example in {DOC}"
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, Any] = {}
    for block in blocks:
        exec(compile(block, str(DOC), "exec"), namespace)
    experiment = namespace["experiment"]
    assert experiment.total_frames == 4_000 and experiment.n_iters_performed == 2
    (run,) = tmp_path.glob("mappo_swarm_nav_mlp__*")
    evaluations = next(run.rglob("eval_reward_episode_reward_mean.csv")).read_text().split()
    assert len(evaluations) == 2  # before training and at its end
