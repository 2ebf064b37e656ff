"""A TorchRL batched env over one batched core: ``batch_size=[B]``, a group of N agents.

:class:`SwarmTorchRLEnv` steps B swarms of N agents in one call of the core
(:func:`swarm_envs.envs.backends.make_core`), as :func:`swarm_envs.swarm_nav_v0.vec_env`
does for SB3, and lays the data out as TorchRL's multi-agent envs do (VMAS, PettingZoo)
with one group, ``"agents"``:

===============================  ==============  =======================================
key                              shape           meaning
===============================  ==============  =======================================
``("agents", "observation")``    ``(B, N, o)``   each agent's local observation, float32
``("agents", "action")``         ``(B, N, d)``   each agent's action in [−1, 1]
``("agents", "reward")``         ``(B, N, 1)``   the swarm's cooperative reward, per agent
``"done"``, ``"terminated"``,    ``(B, 1)``      per swarm: the episode ended; by success;
``"truncated"``                                  by the step limit (``max_steps``)
``"state"`` (``return_state``)   ``(B, N·o)``    every observation of the swarm, as the
                                                 PettingZoo env's ``state()``
===============================  ==============  =======================================

Swarms are reset by TorchRL's ``"_reset"`` mask (a collector resets the swarms that
ended and no others); ``set_seed`` seeds the generator the starts are drawn from, so a
seed gives the same rollout. Agents that stop acting under ``perturbations`` observe
zeros, and the core ignores their actions, as in the SB3 ``vec_env``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from swarm_envs.config import SwarmConfig
from swarm_envs.envs.adapters.inputs import as_action, make_config
from swarm_envs.envs.backends import make_core
from swarm_envs.envs.task import OBS_BOUND
from swarm_envs.envs.task.agent_status import ACTIVE
from train.benchmarl import INSTALL_HINT

try:
    import torch
    from tensordict import TensorDict, TensorDictBase
    from torchrl.data import Bounded, Categorical, Composite, Unbounded
    from torchrl.envs import EnvBase
except ImportError as err:  # pragma: no cover - the extra is installed in CI
    raise ImportError(INSTALL_HINT) from err

#: The name of the one agent group (TorchRL's and BenchMARL's convention).
GROUP = "agents"

__all__ = ["GROUP", "SwarmTorchRLEnv"]


def _check_n_swarms(n_swarms: Any) -> int:
    if isinstance(n_swarms, bool) or not isinstance(n_swarms, (int, np.integer)) or n_swarms < 1:
        raise ValueError(f"n_swarms must be an integer >= 1, got {n_swarms!r}")
    return int(n_swarms)


class SwarmTorchRLEnv(EnvBase):
    """``n_swarms`` swarms as one TorchRL env with ``batch_size=[n_swarms]`` (module docstring).

    Args:
        n_swarms: the batch ``B``.
        config: a YAML config (a name under ``configs/env`` or a path), as for every env.
        return_state: also return ``"state"``, every agent's observation concatenated.
        device: where the tensors live (the core itself runs on its ``backend``).
        **kwargs: :class:`~swarm_envs.config.SwarmConfig` keywords (``task="mill"``,
            ``n_agents=8``, ...); an unknown one raises
            :class:`~swarm_envs.config.UnknownKeyError` (a ``TypeError``).
    """

    def __init__(
        self,
        n_swarms: int = 1,
        config: str | None = None,
        return_state: bool = False,
        device: str | torch.device = "cpu",
        **kwargs: Any,
    ) -> None:
        n_swarms = _check_n_swarms(n_swarms)
        if not isinstance(return_state, (bool, np.bool_)):
            raise ValueError(f"return_state must be True or False, got {return_state!r}")
        self.cfg: SwarmConfig = make_config(
            config,
            kwargs,
            owner="SwarmTorchRLEnv",
            keywords=("n_swarms", "config", "return_state", "device"),
        )
        super().__init__(device=device, batch_size=torch.Size([n_swarms]))
        self.n_swarms = n_swarms
        self.n_agents = self.cfg.n_agents
        self.return_state = bool(return_state)
        self.core = make_core(self.cfg, batch=n_swarms, dtype=np.float32)
        self._rng = np.random.default_rng()
        self._make_specs()

    @property
    def backend(self) -> str:
        """The core's backend (``"native"``, ``"numpy"``, ...)."""
        return self.core.backend

    @property
    def agent_names(self) -> list[str]:
        """``agent_0 … agent_{N−1}``, as the PettingZoo env names them."""
        return [f"agent_{i}" for i in range(self.n_agents)]

    @property
    def group_map(self) -> dict[str, list[str]]:
        """The one group and its agents (BenchMARL's ``group_map``)."""
        return {GROUP: self.agent_names}

    def _make_specs(self) -> None:
        B, N, d, o = self.n_swarms, self.n_agents, self.cfg.dim, self.core.obs_dim
        dev = self.device
        obs = Bounded(-OBS_BOUND, OBS_BOUND, shape=(B, N, o), dtype=torch.float32, device=dev)
        observation = Composite({GROUP: Composite(observation=obs, shape=(B, N))}, shape=(B,))
        if self.return_state:
            observation["state"] = Bounded(
                -OBS_BOUND, OBS_BOUND, shape=(B, N * o), dtype=torch.float32, device=dev
            )
        self.observation_spec = observation
        act = Bounded(-1.0, 1.0, shape=(B, N, d), dtype=torch.float32, device=dev)
        self.action_spec = Composite({GROUP: Composite(action=act, shape=(B, N))}, shape=(B,))
        rew = Unbounded(shape=(B, N, 1), dtype=torch.float32, device=dev)
        self.reward_spec = Composite({GROUP: Composite(reward=rew, shape=(B, N))}, shape=(B,))
        flag = Categorical(2, shape=(B, 1), dtype=torch.bool, device=dev)
        self.done_spec = Composite(
            done=flag, terminated=flag.clone(), truncated=flag.clone(), shape=(B,)
        )

    # ------------------------------------------------------------------ EnvBase API
    def _set_seed(self, seed: int | None) -> None:
        self._rng = np.random.default_rng(seed)

    def _observation(self) -> dict[str, Any]:
        obs = self.core.observe()
        status = getattr(self.core, "status", None)
        if status is not None:
            obs[status != ACTIVE] = 0.0
        t = torch.from_numpy(obs).to(self.device)
        out: dict[str, Any] = {GROUP: TensorDict({"observation": t}, batch_size=t.shape[:2])}
        if self.return_state:
            out["state"] = t.reshape(self.n_swarms, -1)
        return out

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        which = None
        if tensordict is not None and "_reset" in tensordict.keys():
            mask = tensordict.get("_reset").reshape(self.n_swarms).cpu().numpy()
            which = None if mask.all() else mask
        if which is None or which.any():
            self.core.reset(self._rng, which=which)
        flags = torch.zeros((self.n_swarms, 1), dtype=torch.bool, device=self.device)
        return TensorDict(
            {
                **self._observation(),
                "done": flags,
                "terminated": flags.clone(),
                "truncated": flags.clone(),
            },
            batch_size=self.batch_size,
            device=self.device,
        )

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        B, N, d = self.n_swarms, self.n_agents, self.cfg.dim
        action = as_action(tensordict.get((GROUP, "action")), (B, N, d), name="action")
        reward, term, trunc, _ = self.core.step(action)
        terminated = torch.from_numpy(np.asarray(term, bool)).reshape(B, 1)
        truncated = torch.from_numpy(np.asarray(trunc, bool)).reshape(B, 1)
        out = self._observation()
        r = torch.from_numpy(np.asarray(reward, np.float32)).reshape(B, 1, 1)
        out[GROUP]["reward"] = r.expand(B, N, 1).contiguous().to(self.device)
        return TensorDict(
            {
                **out,
                "done": (terminated | truncated).to(self.device),
                "terminated": terminated.to(self.device),
                "truncated": truncated.to(self.device),
            },
            batch_size=self.batch_size,
            device=self.device,
        )
