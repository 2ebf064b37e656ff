"""A native Gymnasium ``VectorEnv``: B SwarmNav swarms stepped in one call of a batched core.

``gym.make_vec("swarm_envs/SwarmNav-v0", num_envs=B)`` builds a
:class:`SwarmNavVectorEnv` (the registered ``vector_entry_point``): sub-env ``i`` is
swarm ``i`` of one batched core, with the single env's spaces batched (observation
``(B, N·obs_dim)`` float32, action ``(B, N·d)`` in [−1, 1]; agent-major, as
:class:`~swarm_envs.envs.adapters.swarm_nav.SwarmNavEnv`). ``vectorization_mode="sync"`` or
``"async"`` still builds B single envs instead.

Autoreset: ``metadata["autoreset_mode"]`` is ``AutoresetMode.NEXT_STEP``, Gymnasium's
default. A sub-env whose episode ends at a step returns that step's last observation
with ``terminated`` or ``truncated`` set; at its next step it is reset instead of
stepped (its action is ignored) and returns the first observation of the new episode,
reward 0, ``terminated = truncated = False`` and the statistics of the new start.

Seeds: sub-env ``i`` draws its starts from a generator of its own, so the vector env
gives the same rollout as B separate ``gym.make`` envs (same config, backend and
``dtype``) reset with ``seed + i`` (or with ``seed[i]`` for a list) and stepped with the
same actions, as ``gym.make_vec(..., vectorization_mode="sync")`` does; a sub-env's
automatic resets continue its own generator. ``reset(seed=None)`` keeps the generators
(fresh ones at the first reset).

Infos: Gymnasium's vector form, ``{key: (B,) array, "_key": (B,) bool}``, one entry per
statistic (:data:`swarm_envs.envs.task.STAT_KEYS`), every mask true.

Episode length: ``max_steps`` of the config, as in the single env (no ``TimeLimit``:
``max_episode_steps`` is refused, pass ``max_steps``). The state is float64 by default,
as in the single env (``dtype=np.float32`` is faster); observations are float32.
Actions follow the input rule of ``docs/inputs.md`` (exactly ``(B, N·d)``, real numeric,
finite; clipped to [−1, 1]).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from swarm_envs.envs.adapters.inputs import as_action, check_seed, make_config
from swarm_envs.envs.backends import make_core
from swarm_envs.envs.common import check_dtype
from swarm_envs.envs.task import OBS_BOUND

__all__ = ["SwarmNavVectorEnv"]


class SwarmNavVectorEnv(VectorEnv):
    """``num_envs`` SwarmNav swarms as one Gymnasium ``VectorEnv`` (one swarm per sub-env).

    Keyword arguments as :class:`~swarm_envs.envs.adapters.swarm_nav.SwarmNavEnv` (``config``,
    every field of the config), plus ``dtype`` of the state. ``render_mode`` is
    ``None`` or ``"rgb_array"`` (:meth:`render` gives one frame per sub-env).
    """

    # A class constant; gymnasium annotates it as an instance variable of VectorEnv.
    metadata: ClassVar[dict[str, Any]] = {  # type: ignore[misc]
        "render_modes": ["rgb_array"],
        "render_fps": 20,
        "autoreset_mode": AutoresetMode.NEXT_STEP,
    }

    def __init__(
        self,
        num_envs: int = 1,
        config: str | None = None,
        render_mode: str | None = None,
        dtype: type = np.float64,
        **kwargs: Any,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)):
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        if num_envs < 1:
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        if "max_episode_steps" in kwargs:
            raise ValueError(
                "max_episode_steps is not an argument of the SwarmNav vector env: the "
                f"episode length is max_steps (got max_episode_steps="
                f"{kwargs['max_episode_steps']!r})"
            )
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        check_dtype(dtype)
        self.cfg = make_config(
            config,
            kwargs,
            owner="SwarmNavVectorEnv",
            keywords=("num_envs", "config", "render_mode", "dtype"),
        )
        self.num_envs = int(num_envs)
        self.render_mode = render_mode
        self.core = make_core(self.cfg, batch=self.num_envs, dtype=dtype)
        n, d = self.cfg.n_agents, self.cfg.dim
        self.single_observation_space = spaces.Box(
            -OBS_BOUND, OBS_BOUND, (n * self.core.obs_dim,), np.float32
        )
        self.single_action_space = spaces.Box(-1.0, 1.0, (n * d,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._rngs: list[np.random.Generator] | None = None
        self._autoreset = np.zeros(self.num_envs, dtype=bool)
        self._needs_reset = True

    @property
    def backend(self) -> str:
        """The backend of the batched core (``"native"``, ``"numpy"``, ...)."""
        return self.core.backend

    def _seeds(self, seed: int | list[int | None] | None) -> list[int | None]:
        B = self.num_envs
        if seed is None:
            return [None] * B
        if isinstance(seed, (list, tuple)):
            if len(seed) != B:
                raise ValueError(
                    f"seed must be None, a non-negative integer or a list of {B} seeds "
                    f"(num_envs), got a list of {len(seed)}"
                )
            return [check_seed(s) for s in seed]
        first = check_seed(seed)
        assert first is not None  # seed is not None here
        return [first + i for i in range(B)]

    def _reset_swarms(self, which: np.ndarray) -> None:
        """New starts for the swarms ``which``, each from its own generator."""
        assert self._rngs is not None
        if which.all() and self.num_envs == 1:
            self.core.reset(self._rngs[0])
            return
        mask = np.zeros(self.num_envs, dtype=bool)
        for b in np.flatnonzero(which).tolist():
            mask[b] = True
            self.core.reset(self._rngs[b], which=mask)
            mask[b] = False

    def _infos(self, stats: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        mask = np.ones(self.num_envs, dtype=bool)
        infos: dict[str, np.ndarray] = {}
        for key, value in stats.items():
            infos[key] = np.asarray(value, dtype=np.float64)
            infos[f"_{key}"] = mask
        return infos

    def reset(
        self,
        *,
        seed: int | list[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset the sub-envs (all, or those of ``options["reset_mask"]``, a bool
        ``(num_envs,)`` array). ``seed``: ``None`` (keep each sub-env's generator), a
        non-negative integer (sub-env ``i`` gets ``seed + i``) or a list of
        ``num_envs`` seeds (``None`` entries: fresh entropy)."""
        seeds = self._seeds(seed)
        which = np.ones(self.num_envs, dtype=bool)
        if options is not None and "reset_mask" in options:
            mask = np.asarray(options["reset_mask"])
            if mask.dtype != np.bool_ or mask.shape != (self.num_envs,):
                raise ValueError(
                    f"options['reset_mask'] must be a bool array of shape ({self.num_envs},)"
                    f", got dtype {mask.dtype} and shape {mask.shape}"
                )
            if self._needs_reset and not mask.all():
                raise ValueError(
                    "options['reset_mask'] must select every sub-env at the first reset"
                )
            which = mask
        if self._rngs is None:
            self._rngs = [np.random.default_rng(s) for s in seeds]
        else:
            for b in np.flatnonzero(which).tolist():
                if seeds[b] is not None or seed is not None:
                    self._rngs[b] = np.random.default_rng(seeds[b])
        self._reset_swarms(which)
        self._autoreset[which] = False
        self._needs_reset = False
        return self.core.observe().reshape(self.num_envs, -1), self._infos(self.core.stats())

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every sub-env; those that ended at the previous step are reset instead
        (NEXT_STEP autoreset, see the module docstring)."""
        if self._needs_reset:
            raise RuntimeError("step() called before reset(); call reset()")
        B, n, d = self.num_envs, self.cfg.n_agents, self.cfg.dim
        a = as_action(actions, (B, n * d)).reshape(B, n, d)
        reward, terminated, truncated, stats = self.core.step(a)
        reward = np.asarray(reward, dtype=np.float64)
        terminated, truncated = np.asarray(terminated), np.asarray(truncated)
        restart = self._autoreset
        if restart.any():
            # Stepped with the others (the core steps every swarm), then restarted: their
            # step is discarded, and the new episode's first observation is returned.
            self._reset_swarms(restart)
            fresh = self.core.stats()
            for key in stats:
                stats[key] = np.where(restart, fresh[key], stats[key])
            reward = np.where(restart, 0.0, reward)
            terminated = terminated & ~restart
            truncated = truncated & ~restart
        self._autoreset = terminated | truncated
        obs = self.core.observe().reshape(B, -1)
        return obs, reward, terminated, truncated, self._infos(stats)

    # gymnasium types the frames with a type variable that no concrete frame type matches.
    def render(self) -> tuple[np.ndarray, ...] | None:  # type: ignore[override]
        """``rgb_array``: one uint8 ``(H, W, 3)`` frame per sub-env; else ``None``."""
        if self.render_mode is None:
            return None
        from swarm_envs.render import draw_swarm

        x, v, goal = self.core.x, self.core.v, self.core.goal
        return tuple(
            draw_swarm(x[b], goal=goal[b], goal_radius=self.cfg.arrival_radius, velocities=v[b])
            for b in range(self.num_envs)
        )

    def close_extras(self, **kwargs: Any) -> None:
        """Nothing to release: the core holds arrays only."""
