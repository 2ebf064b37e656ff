"""Training configuration: ``configs/train/*.yaml`` → a frozen, validated :class:`TrainConfig`.

Strict like the env configs: unknown keys, unknown SB3 hyperparameters and bad values
raise ``ValueError`` naming the key and what is allowed.

>>> tc = train_config_from_mapping({"algo": "PPO", "total_timesteps": 1000})
>>> tc.mode, tc.n_swarms
('shared', 8)
>>> train_config_from_mapping({"hyperparams": {"learning_rat": 1e-3}})
Traceback (most recent call last):
...
ValueError: hyperparams.learning_rat is not a PPO argument; allowed: ...
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import yaml

from swarm_envs import ENV_ID
from swarm_envs.config import (
    SwarmConfig,
    config_from_mapping,
    load_swarm_config,
    resolve_config_path,
)

ALGOS = ("PPO", "SAC")
MODES = ("shared", "central")
#: SB3 constructor arguments that the trainer sets itself (not allowed in ``hyperparams``).
RESERVED = {"policy", "env", "seed", "device", "policy_kwargs", "tensorboard_log", "verbose"}


def algorithm_class(name: str) -> type:
    """The SB3 class for ``name`` (one of :data:`ALGOS`)."""
    import stable_baselines3

    if name not in ALGOS:
        raise ValueError(f"algo must be one of {ALGOS}, got {name!r}")
    return getattr(stable_baselines3, name)


class RunConfig:
    """What every training run's config shares (SB3's and RLlib's): the env part
    (``env_config`` YAML plus ``env`` overrides), ``net_arch`` and ``hyperparams``.

    A mixin for the frozen dataclasses that declare those fields.
    """

    env_config: str | None  # declared by the subclasses' dataclass fields
    env: Mapping[str, Any]
    net_arch: Any
    hyperparams: Mapping[str, Any]

    def swarm_config(self) -> SwarmConfig:
        """The env configuration this run trains on (YAML, then the ``env`` overrides)."""
        return load_swarm_config(self.env_config, dict(self.env))

    def _check_env(self) -> None:
        try:
            self.swarm_config()
        except ValueError as err:
            raise ValueError(f"env: {err}") from None

    def to_dict(self) -> dict[str, Any]:
        """Plain data for YAML (saved beside the model or checkpoint)."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}  # type: ignore[arg-type]
        out["net_arch"] = list(self.net_arch)
        out["env"] = dict(self.env)
        out["hyperparams"] = dict(self.hyperparams)
        return out


@dataclass(frozen=True)
class TrainConfig(RunConfig):
    """One training run. ``total_timesteps`` counts SB3 timesteps: agent-steps in
    ``shared`` mode (each vector step is ``n_swarms × n_agents`` of them), swarm-steps in
    ``central`` mode."""

    algo: str = "PPO"
    """SB3 algorithm: ``PPO`` or ``SAC``."""
    mode: str = "shared"
    """``shared``: one policy for every agent through ``swarm_nav_v0.vec_env``;
    ``central``: one policy over the whole swarm through the Gymnasium env."""
    env_id: str = ENV_ID
    """Gymnasium id (central mode) and the name recorded in results."""
    env_config: str | None = None
    """Path of an env YAML (``configs/env/...``), or null for the defaults."""
    env: dict = field(default_factory=dict)
    """Overrides of :class:`swarm_envs.config.SwarmConfig` keys (e.g. ``n_agents``)."""
    n_swarms: int = 8
    """Parallel swarms (shared mode: batch of the VecEnv; central: number of envs)."""
    total_timesteps: int = 100_000
    """SB3 timesteps to train for (see the class docstring)."""
    seed: int = 0
    """Seed of the model, the training envs and SB3's global seeding."""
    net_arch: tuple[int, ...] = (64, 64)
    """Hidden layer sizes of the policy and value networks."""
    hyperparams: dict = field(default_factory=dict)
    """Extra SB3 constructor arguments, checked against the algorithm's signature."""
    eval_freq: int = 0
    """Evaluate against the analytic controller every this many timesteps (0 = never)."""
    eval_episodes: int = 10
    """Episodes per periodic evaluation."""
    eval_seed: int = 1_000_000
    """Seed of the evaluation episodes (kept apart from the training seed)."""
    checkpoint_freq: int = 0
    """Save a checkpoint every this many timesteps (0 = only the final model)."""
    device: str = "cpu"
    """Torch device for the networks."""
    torch_threads: int | None = None
    """If set, ``torch.set_num_threads`` for the run (fewer threads: steadier timings)."""

    def __post_init__(self) -> None:
        cls = algorithm_class(self.algo)
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {self.mode!r}")
        for name, low in (
            ("n_swarms", 1),
            ("total_timesteps", 1),
            ("seed", 0),
            ("eval_freq", 0),
            ("eval_episodes", 1),
            ("eval_seed", 0),
            ("checkpoint_freq", 0),
        ):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
        if self.torch_threads is not None and (
            not isinstance(self.torch_threads, int) or self.torch_threads < 1
        ):
            raise ValueError(
                f"torch_threads must be null or an integer >= 1, got {self.torch_threads!r}"
            )
        arch = tuple(self.net_arch)
        if not arch or any(isinstance(h, bool) or not isinstance(h, int) or h < 1 for h in arch):
            raise ValueError(
                f"net_arch must be a non-empty list of integers >= 1, got {self.net_arch!r}"
            )
        object.__setattr__(self, "net_arch", arch)
        if not isinstance(self.env, Mapping):
            raise ValueError(f"env must be a mapping of SwarmConfig keys, got {self.env!r}")
        if not isinstance(self.hyperparams, Mapping):
            raise ValueError(f"hyperparams must be a mapping, got {self.hyperparams!r}")
        allowed = set(inspect.signature(cls.__init__).parameters) - RESERVED - {"self"}
        allowed = {a for a in allowed if not a.startswith("_")}
        for key in self.hyperparams:
            if key not in allowed:
                raise ValueError(
                    f"hyperparams.{key} is not a {self.algo} argument; "
                    f"allowed: {', '.join(sorted(allowed))}"
                )
        self._check_env()  # a typo in the env part fails before any training starts


def train_config_from_mapping(data: Mapping[str, Any]) -> TrainConfig:
    """Build a :class:`TrainConfig` strictly (unknown keys name themselves)."""
    return config_from_mapping(TrainConfig, data)


def parse_overrides(items: list[str]) -> dict[str, Any]:
    """``["total_timesteps=5000", "env.n_agents=4"]`` → nested dict; values parsed as YAML."""
    out: dict[str, Any] = {}
    for item in items:
        if "=" not in item:
            raise ValueError(f"override {item!r} must look like key=value (e.g. seed=3)")
        key, raw = item.split("=", 1)
        value = yaml.safe_load(raw)
        parts = key.split(".")
        node = out
        for part in parts[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ValueError(f"override {item!r} conflicts with another override")
        node[parts[-1]] = value
    return out


def load_train_config(
    path: str | Path | None, overrides: Mapping[str, Any] | None = None
) -> TrainConfig:
    """Load ``configs/train/<name>.yaml`` and merge ``overrides`` (nested dicts merge)."""
    data: dict[str, Any] = {}
    if path is not None:
        p = resolve_config_path(path, "train", "train config")
        data = yaml.safe_load(p.read_text()) or {}
        if not isinstance(data, dict):
            raise ValueError(f"train config {p} must hold a mapping")
    for key, value in (overrides or {}).items():
        if isinstance(value, Mapping) and isinstance(data.get(key), Mapping):
            data[key] = {**data[key], **value}
        else:
            data[key] = value
    return train_config_from_mapping(data)
