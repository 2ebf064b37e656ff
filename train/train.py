"""Train an SB3 policy on SwarmNav from a :class:`~train.config.TrainConfig`.

Two modes:

* ``shared`` (default): one policy for every agent. The env is
  ``swarm_nav_v0.vec_env(n_swarms, ...)``, a native batched VecEnv with one slot per
  agent; all swarms step in one array call (no SuperSuit, no per-env loop).
* ``central``: one policy sees the whole swarm (flat observation, flat action) through
  ``gymnasium.make(env_id)``, ``n_swarms`` copies in a ``DummyVecEnv``.

What a run writes into its output folder: ``model.zip`` (final), ``best_model.zip`` (best
periodic evaluation, if enabled), ``checkpoints/`` (if enabled), ``train_config.yaml``,
``env_config.yaml`` (the resolved env configuration), ``meta.json`` (package versions,
seed, timings) and ``tensorboard/``. ``swarm-eval --config <out>/env_config.yaml
--policies potential <out>/model.zip`` evaluates it.

Reproducibility: the same config and seed give the same model on the same machine and
software versions (CPU). Limits: results differ across torch/numpy versions and CPU
instruction sets (reductions may be vectorised differently), and on GPUs unless torch's
deterministic algorithms are enabled; ``torch_threads`` fixes the thread count, which
torch's CPU kernels may otherwise choose per machine.
"""

from __future__ import annotations

import functools
import json
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml

import swarm_envs
from swarm_envs.config import as_dict
from train.config import TrainConfig, algorithm_class


def make_training_env(tc: TrainConfig):
    """The VecEnv a run trains on, reporting SB3's ``episode`` infos.

    Shared mode: the batched ``SwarmNavVecEnv`` itself (it reports the episodes; a
    ``VecMonitor`` would add a Python loop over all B·N infos per step). Central mode:
    the gym envs in a ``DummyVecEnv`` under ``VecMonitor``.
    """
    from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor

    if tc.mode == "shared":
        venv = swarm_envs.swarm_nav_v0.vec_env(tc.n_swarms, config=tc.env_config, **tc.env)
        venv.seed(tc.seed)
        return venv
    import gymnasium as gym

    def make_one():
        return gym.make(tc.env_id, config=tc.env_config, **tc.env)

    venv = DummyVecEnv([make_one for _ in range(tc.n_swarms)])
    venv.seed(tc.seed)
    return VecMonitor(venv)


@functools.cache
def done_slots_only(cls: type) -> type:
    """SB3 algorithm ``cls`` whose episode bookkeeping visits the slots that ended only.

    SB3's ``_update_info_buffer`` reads ``info.get("episode")`` and ``"is_success"`` of
    every slot on every step: with one slot per agent (32,768 slots at 1,024 swarms × 32
    agents) that loop costs more per step than the env's whole step. Monitors
    (``Monitor``, ``VecMonitor`` and ``SwarmNavVecEnv``) put ``episode`` into the infos
    of ended episodes only, and SB3 counts ``is_success`` only there, so visiting those
    slots keeps what it logs.
    Models save and load as ``cls`` (the override holds no state).
    """

    def _update_info_buffer(self, infos: list[dict[str, Any]], dones: Any = None) -> None:
        if dones is None:
            return cls._update_info_buffer(self, infos, dones)
        ended = np.flatnonzero(dones)
        cls._update_info_buffer(self, [infos[i] for i in ended], np.ones(ended.size, bool))

    return type(
        cls.__name__,
        (cls,),
        {
            "_update_info_buffer": _update_info_buffer,
            "__module__": __name__,
            "__doc__": cls.__doc__,
        },
    )


def build_model(tc: TrainConfig, venv, tensorboard_log: str | None = None):
    """The SB3 model of ``tc`` on ``venv`` (seeded; hyperparameters from the config)."""
    cls = done_slots_only(algorithm_class(tc.algo))
    net = list(tc.net_arch)
    policy_kwargs: dict[str, Any] = {"net_arch": net if tc.algo == "SAC" else dict(pi=net, vf=net)}
    return cls(
        "MlpPolicy",
        venv,
        seed=tc.seed,
        device=tc.device,
        policy_kwargs=policy_kwargs,
        tensorboard_log=tensorboard_log,
        verbose=0,
        **dict(tc.hyperparams),
    )


def train(
    tc: TrainConfig,
    out_dir: str | Path,
    *,
    progress_bar: bool = True,
    tensorboard: bool = True,
    verbose: int = 1,
) -> Path:
    """Train according to ``tc``; write the model and its metadata into ``out_dir``.

    Returns the path of the final ``model.zip``.
    """
    import stable_baselines3
    import torch
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback

    from train.callbacks import AnalyticBaselineEvalCallback, SwarmStatsCallback

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cfg = tc.swarm_config()
    if tc.torch_threads is not None:
        torch.set_num_threads(tc.torch_threads)
    (out / "train_config.yaml").write_text(yaml.safe_dump(tc.to_dict(), sort_keys=False))
    (out / "env_config.yaml").write_text(yaml.safe_dump(as_dict(cfg), sort_keys=False))

    venv = make_training_env(tc)
    tb = str(out / "tensorboard") if tensorboard and _has_tensorboard() else None
    model = build_model(tc, venv, tensorboard_log=tb)
    callbacks: list[Any] = [SwarmStatsCallback(cfg)]
    evaluator = None
    if tc.eval_freq > 0:
        evaluator = AnalyticBaselineEvalCallback(
            cfg, tc.eval_freq, tc.eval_episodes, tc.eval_seed, out, verbose=verbose
        )
        callbacks.append(evaluator)
    if tc.checkpoint_freq > 0:
        callbacks.append(
            CheckpointCallback(
                save_freq=max(tc.checkpoint_freq // venv.num_envs, 1),
                save_path=str(out / "checkpoints"),
                name_prefix="model",
            )
        )
    if verbose:
        print(
            f"training {tc.algo} ({tc.mode}) for {tc.total_timesteps:,} timesteps on "
            f"{venv.num_envs} slots; N = {cfg.n_agents}; out = {out}"
        )
    start = time.perf_counter()
    model.learn(
        total_timesteps=tc.total_timesteps,
        callback=CallbackList(callbacks),
        progress_bar=progress_bar and _has_progress_bar(),
        tb_log_name=tc.algo,
    )
    elapsed = time.perf_counter() - start
    model_path = out / "model.zip"
    model.save(model_path)
    venv.close()
    meta = {
        "swarm_envs": swarm_envs.__version__,
        "stable_baselines3": stable_baselines3.__version__,
        "torch": torch.__version__,
        "numpy": np.__version__,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "algo": tc.algo,
        "mode": tc.mode,
        "seed": tc.seed,
        "total_timesteps": tc.total_timesteps,
        "train_seconds": round(elapsed, 2),
        "evaluations": evaluator.history if evaluator is not None else [],
    }
    (out / "meta.json").write_text(json.dumps(meta, indent=2) + "\n")
    if verbose:
        print(f"saved {model_path} after {elapsed:.0f} s")
    return model_path


def _has_tensorboard() -> bool:
    try:
        import tensorboard  # noqa: F401
    except ImportError:
        return False
    return True


def _has_progress_bar() -> bool:
    try:
        import rich  # noqa: F401
        import tqdm  # noqa: F401
    except ImportError:
        return False
    return True
