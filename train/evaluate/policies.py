"""Which policies fit the env, and how: the ``shared`` / ``central`` layouts; SB3 loading.

A policy without ``observation_space`` / ``action_space`` (a plain object with
``predict``) is taken to be per-agent (``"shared"``), as the :mod:`agents` controllers
are. Stable-Baselines3 is imported by :func:`load_sb3_model` only.
"""

from __future__ import annotations

import dataclasses
import json
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from swarm_envs.config import SwarmConfig
from swarm_envs.envs.task import observation_size
from swarm_envs.envs.task.observation import layout

__all__ = [
    "TRAINED_ENV",
    "SpaceMismatchError",
    "describe_trained_env",
    "load_sb3_model",
    "policy_label",
    "policy_mode",
    "split_label",
    "trained_env_differences",
    "trained_env_record",
]

#: The attribute of an SB3 model that holds the env it was trained on
#: (:func:`trained_env_record`); SB3 saves it in the zip's ``data`` and sets it on load.
TRAINED_ENV = "swarm_env"

#: Keys of the record that change what a policy's observations or actions mean: a
#: policy evaluated where one of them differs is warned about.
MEANING_KEYS = (
    "dynamics",
    "dim",
    "n_neighbors",
    "observation_size",
    "observation_layout",
    "obs_goal_scale",
    "obs_neighbor_scale",
    "obs_velocity_scale",
    "u_max",
)


class SpaceMismatchError(ValueError):
    """A policy's observation/action spaces do not fit the environment."""


def policy_mode(policy: Any, cfg: SwarmConfig) -> str:
    """``"shared"`` or ``"central"``: how ``policy`` sees the swarm of ``cfg``.

    Read from ``policy.observation_space`` and ``policy.action_space`` (SB3 models and
    the :mod:`agents` controllers have them); a policy without them is ``"shared"``.

    Raises:
        SpaceMismatchError: the spaces fit neither the per-agent layout (``Box(-10, 10,
            (obs_dim,))`` → ``Box(-1, 1, (d,))``) nor the flat one (``(N·obs_dim,)`` →
            ``(N·d,)``).
    """
    obs_space = getattr(policy, "observation_space", None)
    act_space = getattr(policy, "action_space", None)
    if obs_space is None and act_space is None:
        return "shared"
    n, d, k = cfg.n_agents, cfg.dim, observation_size(cfg)
    flags = n if cfg.observe_status else 0  # the central env appends every agent's flag
    layouts = {"shared": ((k,), (d,)), "central": ((n * k + flags,), (n * d,))}
    obs_shape = getattr(obs_space, "shape", None)
    act_shape = getattr(act_space, "shape", None)
    expected = (
        f"the env's per-agent spaces (observation ({k},), action ({d},)) or its flat "
        f"spaces (observation ({n * k + flags},), action ({n * d},)), both with actions in "
        "[-1, 1]"
    )
    found = (
        f"observation space {obs_space}, action space {act_space}"
        if obs_space is not None
        else f"action space {act_space}"
    )
    for mode, (o, a) in layouts.items():
        if tuple(obs_shape or ()) == o and tuple(act_shape or ()) == a:
            low = np.asarray(getattr(act_space, "low", -1.0), dtype=np.float64)
            high = np.asarray(getattr(act_space, "high", 1.0), dtype=np.float64)
            if not (np.allclose(low, -1.0) and np.allclose(high, 1.0)):
                break
            return mode
    raise SpaceMismatchError(f"{found}; expected {expected}")


def config_for_policy(policy: Any, cfg: SwarmConfig) -> SwarmConfig:
    """``cfg`` with ``observe_status`` as ``policy``'s observation space has it.

    The status flags are part of the observation layout, not of the scenario: a policy
    trained without them runs, blind to failures, on a scenario whose agents fail, and
    one trained with them sees them on a scenario where none fail. ``cfg`` itself where
    it fits or where neither layout does (:func:`policy_mode` then says why).
    """
    try:
        policy_mode(policy, cfg)
        return cfg
    except SpaceMismatchError:
        other = dataclasses.replace(cfg, observe_status=not cfg.observe_status)
        try:
            policy_mode(policy, other)
        except SpaceMismatchError:
            return cfg
        return other


def trained_env_record(cfg: SwarmConfig, env_id: str) -> dict[str, Any]:
    """What a model trained on ``cfg`` records about its env (plain JSON data).

    ``env_id``, ``dynamics``, ``n_agents``, ``dim``, ``n_neighbors``,
    ``observation_size`` (per agent), ``observation_layout`` (:func:`layout` of
    :mod:`swarm_envs.envs.task.observation`), the observation scales, ``u_max`` and the
    whole resolved ``env_config``.
    """
    from swarm_envs.config import as_dict

    return {
        "env_id": env_id,
        "dynamics": cfg.dynamics,
        "n_agents": cfg.n_agents,
        "dim": cfg.dim,
        "n_neighbors": cfg.n_neighbors,
        "observation_size": observation_size(cfg),
        "observation_layout": layout(cfg),
        "obs_goal_scale": cfg.obs_goal_scale,
        "obs_neighbor_scale": cfg.obs_neighbor_scale,
        "obs_velocity_scale": cfg.obs_velocity_scale,
        "u_max": cfg.u_max,
        "env_config": as_dict(cfg),
    }


#: Keys of the env config that make another task of the same observations: the start
#: law, the success rule and the integration. (``n_agents`` is left out:
#: evaluating a shared policy at other swarm sizes is what size transfer does.)
TASK_KEYS = (
    "task",
    "dt",
    "integrator",
    "init_radius",
    "init_density",
    "init_speed",
    "goal_distance_min",
    "goal_distance_max",
    "goal_distance_scale",
    "goal_radius",
    "success_fraction",
    "informed_fraction",
    "goal_in_physics",
)

#: The physics section of the env config that each dynamics reads.
PHYSICS_SECTION = {
    "social_potential": "physics",
    "zone": "zone",
    "piecewise": "piecewise",
    "lagrangian": "lagrangian",
}

#: At most this many differences are named in one warning.
MAX_NAMED = 8


def trained_env_differences(record: Mapping[str, Any] | None, cfg: SwarmConfig) -> list[str]:
    """How ``cfg`` differs from the env of ``record``, as ``"key: trained X, here Y"``:
    first in what observations and actions mean (:data:`MEANING_KEYS`), then in the
    physics parameters of the dynamics, the start law and the success rule
    (:data:`TASK_KEYS`); empty when it does not or when there is no record.

    >>> from swarm_envs.config import SwarmConfig
    >>> record = trained_env_record(SwarmConfig(), "swarm_envs/SwarmNav-v0")
    >>> trained_env_differences(record, SwarmConfig(goal_distance_max=20.0, n_agents=50))
    ['goal_distance_max: trained 12.0, here 20.0']
    """
    if not isinstance(record, Mapping):
        return []
    here = trained_env_record(cfg, str(record.get("env_id", "")))
    out = [
        f"{key}: trained {record[key]!r}, here {here[key]!r}"
        for key in MEANING_KEYS
        if key in record and record[key] != here[key]
    ]
    trained_cfg, here_cfg = record.get("env_config"), here["env_config"]
    if not isinstance(trained_cfg, Mapping):
        return out
    for key in TASK_KEYS:
        if key in trained_cfg and trained_cfg[key] != here_cfg.get(key):
            out.append(f"{key}: trained {trained_cfg[key]!r}, here {here_cfg.get(key)!r}")
    section = PHYSICS_SECTION.get(cfg.dynamics)
    if cfg.dynamics == record.get("dynamics") and section is not None:
        old, new = trained_cfg.get(section), here_cfg.get(section)
        if isinstance(old, Mapping) and isinstance(new, Mapping):
            out += [
                f"{section}.{k}: trained {old[k]!r}, here {new.get(k)!r}"
                for k in old
                if old[k] != new.get(k)
            ]
    if len(out) > MAX_NAMED:
        out = [*out[:MAX_NAMED], f"and {len(out) - MAX_NAMED} more"]
    return out


def describe_trained_env(policy: Any) -> str | None:
    """``"trained on dynamics=..., N=..., d=..., k=... (observation size ...)"`` for a
    model that records its env (:data:`TRAINED_ENV`), else None."""
    record = getattr(policy, TRAINED_ENV, None)
    if not isinstance(record, Mapping):
        return None
    return (
        f"trained on dynamics={record.get('dynamics')!r}, N={record.get('n_agents')}, "
        f"d={record.get('dim')}, k={record.get('n_neighbors')} "
        f"(observation size {record.get('observation_size')} per agent)"
    )


def _detect_sb3_algorithm(data: Mapping[str, Any]) -> str:
    """Guess the SB3 algorithm of a saved model from its ``data`` JSON."""
    module = str(data.get("policy_class", {}).get("__module__", ""))
    for name in ("sac", "td3", "dqn", "ddpg"):
        if f".{name}." in module:
            return name.upper()
    return "PPO" if "clip_range" in data else "A2C"


def load_sb3_model(path: str | Path, device: str = "cpu") -> Any:
    """Load a Stable-Baselines3 model zip, detecting its algorithm.

    A model saved by ``swarm-train`` has the env it was trained on as its
    :data:`TRAINED_ENV` attribute (:func:`trained_env_record`); others have none. A
    residual model (``TrainConfig.residual``) comes back as the policy it acts as, its
    baseline plus its correction (:class:`train.residual.ResidualPolicy`).
    The algorithm is read from the zip's ``data`` JSON (the policy class's module and
    algorithm-specific keys), then PPO, SAC, A2C, TD3 and DQN are tried in turn.

    Raises:
        FileNotFoundError: no file at ``path``.
        ValueError: the file is not a model zip any of those algorithms can load.
    """
    import zipfile

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"model file not found: {p}")
    try:
        with zipfile.ZipFile(p) as zf:
            data = json.loads(zf.read("data"))
    except (zipfile.BadZipFile, KeyError, json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"{p} is not a Stable-Baselines3 model zip ({err})") from None
    import stable_baselines3 as sb3

    first = _detect_sb3_algorithm(data)
    order = [first] + [a for a in ("PPO", "SAC", "A2C", "TD3", "DQN") if a != first]
    errors = []
    from train.residual import as_policy

    for name in order:
        cls = getattr(sb3, name)
        try:
            model = cls.load(p, device=device)
        except Exception as err:  # wrong algorithm: try the next one
            errors.append(f"{name}: {type(err).__name__}: {err}")
            continue
        return as_policy(model)
    raise ValueError(f"could not load {p} with any SB3 algorithm: " + "; ".join(errors))


#: What a user-given policy label may hold: it names table rows and files
#: (``episode0_<label>.gif``).
LABEL = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]*")
#: File and folder names that say nothing about which run a policy comes from.
_GENERIC = ("model", "checkpoint")
#: Other names a run writes, kept after its folder's name.
_RUN_FILES = ("best_model",)


def split_label(spec: str) -> tuple[str | None, str]:
    """``"robust=runs/robust/model.zip"`` -> ``("robust", "runs/robust/model.zip")``.

    A spec without ``=`` has no label (``None``). Raises :class:`ValueError` for an
    empty label or one outside :data:`LABEL` (letters, digits, ``_.+-``).

    >>> split_label("robust=runs/robust/model.zip")
    ('robust', 'runs/robust/model.zip')
    >>> split_label("analytic")
    (None, 'analytic')
    """
    label, sep, target = spec.partition("=")
    if not sep:
        return None, spec
    if not LABEL.fullmatch(label) or not target:
        raise ValueError(
            f"policy {spec!r}: give LABEL=POLICY with a label of letters, digits and _.+- "
            "(e.g. robust=runs/robust/model.zip)"
        )
    return label, target


def policy_label(path: str | Path) -> str:
    """The default label of a model file or checkpoint: the name of its run's folder.

    ``model.zip`` and ``checkpoint`` stand for their run's folder, ``best_model.zip``
    adds its name to the folder's, a periodic checkpoint (``<run>/checkpoints/<step>``)
    is ``<run>_<step>``, and any other file keeps its own name.

    >>> policy_label("runs/robust/model.zip")
    'robust'
    >>> policy_label("runs/robust/best_model.zip")
    'robust_best_model'
    >>> policy_label("runs/demo_rllib/checkpoint")
    'demo_rllib'
    >>> policy_label("runs/demo/checkpoints/step_000000512000/model.zip")
    'demo_step_000000512000'
    >>> policy_label("runs/demo_rllib/checkpoints/iter_000010")
    'demo_rllib_iter_000010'
    >>> policy_label("downloads/ppo_nav.zip")
    'ppo_nav'
    >>> policy_label("model.zip")
    'model'
    """
    parts = [p for p in Path(path).with_suffix("").parts if p not in ("", ".", "/")]
    if not parts:
        return "model"
    if len(parts) >= 2 and parts[-1] in _GENERIC:
        parts = parts[:-1]
    elif len(parts) >= 2 and parts[-1] in _RUN_FILES:
        return f"{parts[-2]}_{parts[-1]}"
    if len(parts) >= 3 and parts[-2] == "checkpoints":
        return f"{parts[-3]}_{parts[-1]}"
    return parts[-1]
