"""A trained RLlib checkpoint as a policy with SB3's ``predict``, beside the other policies.

:class:`RLlibPolicy` wraps the shared ``RLModule`` of a checkpoint written by
:func:`train.rllib.train.train_rllib` (or any RLlib new-API-stack checkpoint whose
module maps one agent's observation to its action) and exposes what
:mod:`train.evaluate` and ``swarm-eval`` use:

- ``predict(obs, state=None, episode_start=None, deterministic=True) -> (action,
  state)``: per-agent observations ``(..., obs_dim)`` → actions ``(..., d)`` (so
  ``(n_agents, obs_dim)`` → ``(n_agents, d)``, and the evaluator's ``(B·N, obs_dim)``
  in one call), or a PettingZoo dict ``{agent: obs}`` → ``{agent: action}``;
- ``observation_space`` / ``action_space``: the module's per-agent spaces, so the
  evaluator sees the ``shared`` layout.

Deterministic actions are the mode of the action distribution (the Gaussian's mean);
stochastic ones are drawn with torch under a seed taken from this policy's own
``numpy`` generator (``seed=``), so they repeat for a seed. Either way they are clipped
to the action space, as RLlib's module-to-env connector does in training (the env's
``[-1, 1]`` box makes its un-squashing the identity). The observations go to the module
as they are: the training config adds no observation filter.

Loading needs Ray (``ray.rllib``) but no running Ray instance.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from train.rllib import POLICY_ID
from train.rllib.cluster import require_ray

__all__ = [
    "RLlibPolicy",
    "find_module_dir",
    "is_rllib_checkpoint",
    "load_rllib_policy",
    "rllib_policy_name",
]

#: Where the learner's modules sit inside an algorithm checkpoint.
_MODULES = Path("learner_group") / "learner" / "rl_module"


def _is_module_dir(p: Path) -> bool:
    return (p / "class_and_ctor_args.pkl").is_file() and (p / "module_state.pkl").exists()


def find_module_dir(path: str | Path, module_id: str = POLICY_ID) -> Path:
    """The folder of module ``module_id`` in an RLlib checkpoint.

    ``path`` may be an algorithm checkpoint (``<out>/checkpoint``), a training run's
    output folder (its ``checkpoint/`` is used), the ``rl_module`` folder of a
    checkpoint, or the module's own folder. A relative ``path`` is taken from the
    current folder; the folder returned is absolute (Ray's loaders read URIs, and a
    relative path is not one).

    Raises:
        FileNotFoundError: nothing at ``path``.
        ValueError: ``path`` holds no RLlib module ``module_id``.
    """
    p = Path(path).expanduser().resolve()
    if not p.exists():
        raise FileNotFoundError(f"RLlib checkpoint not found: {p}")
    for root in (p, p / "checkpoint"):
        for candidate in (root / _MODULES / module_id, root / module_id):
            if _is_module_dir(candidate):
                return candidate
    if _is_module_dir(p) and not (p / module_id).exists():
        return p
    raise ValueError(
        f"{p} is not an RLlib checkpoint with module {module_id!r} (looked for "
        f"{_MODULES / module_id} inside it)"
    )


def is_rllib_checkpoint(path: str | Path, module_id: str = POLICY_ID) -> bool:
    """Whether ``path`` is a folder :func:`find_module_dir` accepts (no Ray needed).

    >>> is_rllib_checkpoint("no/such/folder")
    False
    """
    p = Path(path)
    if not p.is_dir():
        return False
    try:
        find_module_dir(p, module_id)
    except (ValueError, FileNotFoundError):
        return False
    return True


class RLlibPolicy:
    """An RLlib ``RLModule`` with SB3's ``predict`` (see the module docstring).

    Args:
        module: a torch ``RLModule`` whose ``forward_inference`` gives
            ``action_dist_inputs`` for a batch of observations.
        seed: seed of the stochastic actions (``deterministic=False``).
        name: label used by ``swarm-eval``.
    """

    def __init__(self, module: Any, *, seed: int | None = None, name: str = "rllib") -> None:
        self.module = module
        self.name = name
        self.observation_space = module.observation_space
        self.action_space = module.action_space
        obs_shape = tuple(getattr(self.observation_space, "shape", ()) or ())
        act_shape = tuple(getattr(self.action_space, "shape", ()) or ())
        if len(obs_shape) != 1 or len(act_shape) != 1:
            raise ValueError(
                f"RLlibPolicy needs flat Box spaces; the module has observation space "
                f"{self.observation_space} and action space {self.action_space}"
            )
        self.obs_dim, self.act_dim = obs_shape[0], act_shape[0]
        self._low = np.asarray(self.action_space.low, dtype=np.float32)
        self._high = np.asarray(self.action_space.high, dtype=np.float32)
        self._rng = np.random.default_rng(seed)
        self._dist_cls = module.get_inference_action_dist_cls()
        module.eval()

    @classmethod
    def load(
        cls, path: str | Path, *, module_id: str = POLICY_ID, seed: int | None = None
    ) -> RLlibPolicy:
        """Load module ``module_id`` from a checkpoint (see :func:`find_module_dir`)."""
        module_dir = find_module_dir(path, module_id)
        require_ray()
        from ray.rllib.core.rl_module.rl_module import RLModule

        module = RLModule.from_checkpoint(module_dir)
        return cls(module, seed=seed, name=rllib_policy_name(path))

    def __repr__(self) -> str:
        return f"RLlibPolicy({self.name!r}, obs_dim={self.obs_dim}, act_dim={self.act_dim})"

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[Any, Any]:
        """Actions for per-agent observations, SB3-style: returns ``(action, state)``.

        Args:
            observation: ``(..., obs_dim)`` → ``(..., d)`` float32, or a PettingZoo dict
                ``{agent: (obs_dim,)}`` → ``{agent: (d,)}``.
            state: passed through (the module is memoryless).
            episode_start: ignored (SB3 compatibility).
            deterministic: the distribution's mode if true, else a seeded sample.

        Raises:
            ValueError: the last axis is not ``obs_dim``, or the input is not numeric.
        """
        del episode_start
        if isinstance(observation, Mapping):
            keys = list(observation)
            if not keys:
                return {}, state
            stacked = np.stack([np.asarray(observation[k]) for k in keys])
            actions, _ = self.predict(stacked, deterministic=deterministic)
            return {k: actions[i] for i, k in enumerate(keys)}, state
        obs = np.asarray(observation)
        if obs.dtype == object or not (
            np.issubdtype(obs.dtype, np.floating) or np.issubdtype(obs.dtype, np.integer)
        ):
            raise ValueError(f"observation must be a numeric array, got dtype {obs.dtype}")
        if obs.ndim == 0 or obs.shape[-1] != self.obs_dim:
            raise ValueError(
                f"observation has shape {obs.shape}; its last axis must be {self.obs_dim} "
                "(one agent's observation)"
            )
        flat = obs.reshape(-1, self.obs_dim).astype(np.float32, copy=False)
        actions = self._actions(flat, deterministic)
        actions = np.clip(actions, self._low, self._high)
        return actions.reshape((*obs.shape[:-1], self.act_dim)), state

    def _actions(self, obs: np.ndarray, deterministic: bool) -> np.ndarray:
        import torch
        from ray.rllib.core.columns import Columns

        with torch.no_grad():
            out = self.module.forward_inference({Columns.OBS: torch.from_numpy(obs)})
            dist = self._dist_cls.from_logits(out[Columns.ACTION_DIST_INPUTS])
            if deterministic:
                action = dist.to_deterministic().sample()
            else:
                seed = int(self._rng.integers(2**63 - 1))
                with torch.random.fork_rng(devices=[]):
                    torch.manual_seed(seed)
                    action = dist.sample()
        return action.cpu().numpy().astype(np.float32, copy=False)


def rllib_policy_name(path: str | Path) -> str:
    """A short label for a checkpoint: its run folder's name for ``<run>/checkpoint``
    (:func:`train.evaluate.policies.policy_label`, the rule of every policy file).

    >>> rllib_policy_name("runs/demo_rllib/checkpoint")
    'demo_rllib'
    >>> rllib_policy_name("runs/demo_rllib/checkpoints/iter_000010")
    'demo_rllib_iter_000010'
    """
    from train.evaluate.policies import policy_label

    return policy_label(path)


def load_rllib_policy(
    path: str | Path, *, module_id: str = POLICY_ID, seed: int | None = None
) -> RLlibPolicy:
    """:meth:`RLlibPolicy.load`: the policy of an RLlib checkpoint, for ``predict``."""
    return RLlibPolicy.load(path, module_id=module_id, seed=seed)
