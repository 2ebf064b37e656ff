"""Train PPO with Ray RLlib on the PettingZoo SwarmNav env: one policy shared by all agents.

RLlib's new API stack (Ray 2.60: ``RLModule``, ``Learner``, ``EnvRunner``). The env is
:mod:`train.rllib.env`'s adapter over ``swarm_nav_v0.parallel_env``; every agent maps
to the one module :data:`~train.rllib.POLICY_ID` (parameter sharing, as the SB3
``shared`` mode does). The config's ``num_env_runners × num_envs_per_env_runner``
swarms are sampled in parallel by Ray actors, and ``num_learners`` learner actors share
each update; on a cluster they spread over its machines.

What a run writes into its output folder:

- ``checkpoint/``: the final RLlib checkpoint (``Algorithm.save_to_path``); the policy
  is ``checkpoint/learner_group/learner/rl_module/shared``. ``swarm-eval --policies
  <out>/checkpoint`` evaluates it (:mod:`train.rllib.policy`), and
  ``Algorithm.from_checkpoint`` resumes training from it;
- ``checkpoints/iter_NNNNNN/`` every ``checkpoint_freq`` iterations;
- ``train_config.yaml``, ``env_config.yaml`` (the resolved env), ``progress.csv`` (one
  row per iteration) and ``meta.json`` (versions, seed, timings, the same history).

Reproducibility: RLlib is seeded with ``seed`` (``config.debugging(seed=...)``), which
also seeds each env runner's envs. With ``num_env_runners: 0`` (sampling in the driver)
two runs of the same config give identical checkpoints on the same machine and
versions. With remote env runners (Ray actors) they do not, in Ray 2.60: the same seed
gives returns that differ slightly from the first iteration on. Such runs are
repeatable in distribution, not bit for bit.
"""

from __future__ import annotations

import csv
import json
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml

import swarm_envs
from swarm_envs.config import as_dict
from train.rllib import POLICY_ID
from train.rllib.cluster import ray_session, require_ray
from train.rllib.config import RLlibTrainConfig

__all__ = ["build_algorithm_config", "shared_policy", "train_rllib"]

#: Columns of ``progress.csv`` (and of each entry of ``meta.json``'s ``history``).
#: RLlib's ``episode_return_mean`` sums the rewards of all agents; the reward is
#: cooperative (every agent gets the same), so ``agent_return_mean`` (divided by N) is
#: the return ``swarm-eval`` reports.
PROGRESS_KEYS = (
    "iteration",
    "env_steps",
    "agent_steps",
    "episodes",
    "episode_return_mean",
    "agent_return_mean",
    "episode_len_mean",
    "time_s",
)


def shared_policy(agent_id: Any, episode: Any = None, **kwargs: Any) -> str:
    """RLlib's ``policy_mapping_fn``: every agent uses the one shared module."""
    return POLICY_ID


def build_algorithm_config(rc: RLlibTrainConfig) -> Any:
    """The ``PPOConfig`` of ``rc`` (needs Ray; registers the env under its name).

    ``build_algorithm_config(rc).build_algo()`` is the algorithm :func:`train_rllib`
    trains; call it inside a Ray session (:func:`train.rllib.cluster.ray_session`).
    """
    require_ray()
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    from train.rllib.env import register

    name = register()
    learners: dict[str, Any] = {
        "num_learners": rc.num_learners,
        "num_gpus_per_learner": rc.num_gpus_per_learner,
    }
    if rc.num_learners > 0:
        learners["num_cpus_per_learner"] = rc.num_cpus_per_learner
    model = DefaultModelConfig(fcnet_hiddens=list(rc.net_arch), vf_share_layers=rc.vf_share_layers)
    return (
        PPOConfig()
        .environment(name, env_config=as_dict(rc.swarm_config()))
        .framework("torch")
        .env_runners(
            num_env_runners=rc.num_env_runners,
            num_envs_per_env_runner=rc.num_envs_per_env_runner,
            num_cpus_per_env_runner=rc.num_cpus_per_env_runner,
            rollout_fragment_length=rc.rollout_fragment_length,
        )
        .learners(**learners)
        .multi_agent(policies={POLICY_ID}, policy_mapping_fn=shared_policy)
        .rl_module(
            rl_module_spec=MultiRLModuleSpec(
                rl_module_specs={POLICY_ID: RLModuleSpec(model_config=model)}
            )
        )
        .training(**dict(rc.hyperparams))
        .debugging(seed=rc.seed)
    )


def _number(value: Any) -> float | None:
    """A finite float, or ``None`` (RLlib reports NaN when no episode finished)."""
    try:
        out = float(value)
    except (TypeError, ValueError):
        return None
    return out if np.isfinite(out) else None


def _progress_row(result: dict[str, Any], n_agents: int, elapsed: float) -> dict[str, Any]:
    runners = result.get("env_runners", {}) or {}
    env_steps = int(result.get("num_env_steps_sampled_lifetime", 0) or 0)
    ret = _number(runners.get("episode_return_mean"))
    return {
        "iteration": int(result.get("training_iteration", 0)),
        "env_steps": env_steps,
        "agent_steps": env_steps * n_agents,
        "episodes": int(_number(runners.get("num_episodes_lifetime")) or 0),
        "episode_return_mean": ret,
        "agent_return_mean": None if ret is None else ret / n_agents,
        "episode_len_mean": _number(runners.get("episode_len_mean")),
        "time_s": round(elapsed, 3),
    }


def train_rllib(
    rc: RLlibTrainConfig,
    out_dir: str | Path,
    *,
    address: str | None = None,
    num_cpus: int | None = None,
    verbose: int = 1,
) -> Path:
    """Train according to ``rc`` on a local Ray or the cluster at ``address``.

    Args:
        rc: the run's configuration.
        out_dir: output folder (created).
        address: a running Ray cluster to join (``HOST:PORT``, ``auto``); ``None``
            starts a local Ray with ``num_cpus`` (default ``rc.num_cpus``) CPUs.
        num_cpus: CPUs of the local Ray; overrides ``rc.num_cpus``.
        verbose: 1 prints one line per iteration; 0 is quiet.

    Returns:
        The folder of the final checkpoint, ``out_dir/checkpoint``.

    Raises:
        ImportError: Ray is not installed.
    """
    require_ray()
    import torch

    out = Path(out_dir).resolve()
    out.mkdir(parents=True, exist_ok=True)
    cfg = rc.swarm_config()
    (out / "train_config.yaml").write_text(yaml.safe_dump(rc.to_dict(), sort_keys=False))
    (out / "env_config.yaml").write_text(yaml.safe_dump(as_dict(cfg), sort_keys=False))
    history: list[dict[str, Any]] = []
    cpus = rc.num_cpus if num_cpus is None else num_cpus
    with ray_session(address, num_cpus=cpus, verbose=bool(verbose)) as ray:
        algo = build_algorithm_config(rc).build_algo()
        try:
            if verbose:
                print(
                    f"training RLlib {rc.algo} (one shared policy) for {rc.iterations} "
                    f"iterations; N = {cfg.n_agents}; {rc.num_env_runners} env runner(s) × "
                    f"{rc.num_envs_per_env_runner} env(s), {rc.num_learners} learner(s); "
                    f"out = {out}"
                )
            start = time.perf_counter()
            for i in range(1, rc.iterations + 1):
                result = algo.train()
                row = _progress_row(result, cfg.n_agents, time.perf_counter() - start)
                history.append(row)
                if verbose:
                    ret = row["agent_return_mean"]
                    print(
                        f"iter {i:4d}/{rc.iterations}  env steps {row['env_steps']:>9,}  "
                        f"agent steps {row['agent_steps']:>11,}  return "
                        f"{'n/a' if ret is None else f'{ret:8.3f}'}  {row['time_s']:7.1f} s"
                    )
                if rc.checkpoint_freq and i % rc.checkpoint_freq == 0 and i < rc.iterations:
                    algo.save_to_path(str(out / "checkpoints" / f"iter_{i:06d}"))
            elapsed = time.perf_counter() - start
            checkpoint = Path(algo.save_to_path(str(out / "checkpoint")))
        finally:
            algo.stop()
        ray_version = ray.__version__
    with (out / "progress.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=PROGRESS_KEYS)
        writer.writeheader()
        writer.writerows(history)
    meta = {
        "engine": "rllib",
        "swarm_envs": swarm_envs.__version__,
        "ray": ray_version,
        "torch": torch.__version__,
        "numpy": np.__version__,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "algo": rc.algo,
        "policy_id": POLICY_ID,
        "seed": rc.seed,
        "iterations": rc.iterations,
        "address": address,
        "train_seconds": round(elapsed, 2),
        "checkpoint": str(checkpoint),
        "history": history,
    }
    (out / "meta.json").write_text(json.dumps(meta, indent=2) + "\n")
    if verbose:
        print(f"saved {checkpoint} after {elapsed:.0f} s")
    return checkpoint
