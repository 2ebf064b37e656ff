"""RLlib training configuration: ``configs/train/*_rllib.yaml`` → :class:`RLlibTrainConfig`.

Strict like :mod:`train.config`: unknown keys, unknown PPO hyperparameters and bad
values raise ``ValueError`` naming the key and what is allowed. Loading a config does
not need Ray.

>>> rc = rllib_config_from_mapping({"iterations": 3, "env": {"n_agents": 4}})
>>> rc.num_env_runners, rc.swarm_config().n_agents
(1, 4)
>>> rllib_config_from_mapping({"iteration": 3})
Traceback (most recent call last):
...
ValueError: unknown config key 'iteration'; allowed keys: ...
>>> rllib_config_from_mapping({"hyperparams": {"learning_rate": 1e-3}})
Traceback (most recent call last):
...
ValueError: hyperparams.learning_rate is not a PPO training argument; allowed: ...
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from swarm_envs.config import config_from_mapping, resolve_config_path
from train.config import RunConfig, env_overrides, net_arch_tuple, read_yaml_mapping
from train.integers import check_integer

__all__ = [
    "ALGOS",
    "PPO_TRAINING_ARGS",
    "RLlibTrainConfig",
    "load_rllib_config",
    "rllib_config_from_mapping",
]

ALGOS = ("PPO",)

#: Arguments of ``PPOConfig.training()`` (Ray 2.60, new API stack) that ``hyperparams``
#: may set. The model is set by ``net_arch`` / ``vf_share_layers``; the learner classes
#: and connectors by the trainer. ``train_batch_size_per_learner`` and
#: ``minibatch_size`` count env steps, each of which holds ``n_agents`` agent steps.
PPO_TRAINING_ARGS = frozenset(
    {
        "gamma",
        "lr",
        "lambda_",
        "clip_param",
        "vf_clip_param",
        "vf_loss_coeff",
        "entropy_coeff",
        "use_kl_loss",
        "kl_coeff",
        "kl_target",
        "use_gae",
        "use_critic",
        "grad_clip",
        "grad_clip_by",
        "train_batch_size_per_learner",
        "minibatch_size",
        "num_epochs",
        "shuffle_batch_per_epoch",
    }
)


@dataclass(frozen=True)
class RLlibTrainConfig(RunConfig):
    """One RLlib run: PPO on ``swarm_nav_v0.parallel_env``, one policy for all agents.

    What scales what: ``num_env_runners × num_envs_per_env_runner`` swarms are sampled
    in parallel (each env runner is a Ray actor, anywhere in the cluster);
    ``num_learners`` learner actors split each training batch and average gradients
    (data-parallel, optionally one GPU each).
    """

    algo: str = "PPO"
    """RLlib algorithm (``PPO``)."""
    env_config: str | None = None
    """Path of an env YAML (``configs/env/...``), or null for the defaults."""
    env: dict = field(default_factory=dict)
    """Overrides of :class:`swarm_envs.config.SwarmConfig` keys (e.g. ``n_agents``)."""
    seed: int = 0
    """Seed of RLlib (networks, sampling) and of each env runner's envs."""
    iterations: int = 10
    """Training iterations (``Algorithm.train()`` calls; one batch each)."""
    num_env_runners: int = 1
    """Sampling actors; 0 samples in the driver process."""
    num_envs_per_env_runner: int = 1
    """Swarms each env runner steps (vectorised inside the actor)."""
    num_cpus_per_env_runner: int = 1
    """CPUs Ray reserves per env runner."""
    num_learners: int = 0
    """Learner actors (data-parallel); 0 learns in the driver process."""
    num_cpus_per_learner: int = 1
    """CPUs Ray reserves per learner actor (when ``num_learners > 0``)."""
    num_gpus_per_learner: float = 0.0
    """GPUs per learner (0: CPU). With ``num_learners = 0`` a GPU serves the driver."""
    num_cpus: int | None = None
    """CPUs of the local Ray this run starts (null: all); ignored with ``--address``."""
    net_arch: tuple[int, ...] = (64, 64)
    """Hidden layer sizes of the policy (and value) network."""
    vf_share_layers: bool = False
    """Share the hidden layers between the policy and the value function."""
    rollout_fragment_length: int | str = "auto"
    """Env steps per env-runner sample call, or ``auto`` (batch / runners)."""
    hyperparams: dict = field(default_factory=dict)
    """``PPOConfig.training()`` arguments (:data:`PPO_TRAINING_ARGS`)."""
    checkpoint_freq: int = 0
    """Save ``checkpoints/iter_NNNNNN`` every this many iterations (0: only the final)."""

    def __post_init__(self) -> None:
        if self.algo not in ALGOS:
            raise ValueError(f"algo must be one of {ALGOS}, got {self.algo!r}")
        for name, low in (
            ("seed", 0),
            ("iterations", 1),
            ("num_env_runners", 0),
            ("num_envs_per_env_runner", 1),
            ("num_cpus_per_env_runner", 1),
            ("num_learners", 0),
            ("num_cpus_per_learner", 1),
            ("checkpoint_freq", 0),
        ):
            object.__setattr__(self, name, check_integer(name, getattr(self, name), low=low))
        if self.num_cpus is not None:
            object.__setattr__(self, "num_cpus", check_integer("num_cpus", self.num_cpus, low=1))
        gpus = self.num_gpus_per_learner
        if (
            isinstance(gpus, bool)
            or not isinstance(gpus, (int, float))
            or not (math.isfinite(gpus) and gpus >= 0)
        ):
            raise ValueError(f"num_gpus_per_learner must be a number >= 0, got {gpus!r}")
        if not isinstance(self.vf_share_layers, bool):
            raise ValueError(f"vf_share_layers must be true or false, got {self.vf_share_layers!r}")
        rfl = self.rollout_fragment_length
        if rfl != "auto":
            try:
                rfl = check_integer("rollout_fragment_length", rfl, low=1)
                object.__setattr__(self, "rollout_fragment_length", rfl)
            except ValueError:
                raise ValueError(
                    f"rollout_fragment_length must be 'auto' or an integer >= 1, got {rfl!r}"
                ) from None
        object.__setattr__(self, "net_arch", net_arch_tuple(self.net_arch))
        object.__setattr__(self, "env", env_overrides(self.env))
        if not isinstance(self.hyperparams, Mapping):
            raise ValueError(f"hyperparams must be a mapping, got {self.hyperparams!r}")
        for key in self.hyperparams:
            if key not in PPO_TRAINING_ARGS:
                raise ValueError(
                    f"hyperparams.{key} is not a PPO training argument; "
                    f"allowed: {', '.join(sorted(PPO_TRAINING_ARGS))}"
                )
        self._check_env()  # a typo in the env part fails before Ray starts


def rllib_config_from_mapping(data: Mapping[str, Any]) -> RLlibTrainConfig:
    """Build an :class:`RLlibTrainConfig` strictly (unknown keys name themselves)."""
    return config_from_mapping(RLlibTrainConfig, data)


def load_rllib_config(
    path: str | Path | None, overrides: Mapping[str, Any] | None = None
) -> RLlibTrainConfig:
    """Load ``configs/train/<name>_rllib.yaml`` and merge ``overrides`` (sections merge)."""
    data: dict[str, Any] = {}
    if path is not None:
        data = read_yaml_mapping(resolve_config_path(path, "train", "train config"), "train config")
    for key, value in (overrides or {}).items():
        if isinstance(value, Mapping) and isinstance(data.get(key), Mapping):
            data[key] = {**data[key], **value}
        else:
            data[key] = value
    return rllib_config_from_mapping(data)
