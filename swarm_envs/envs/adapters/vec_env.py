"""A native batched Stable-Baselines3 ``VecEnv``: B swarms × N agents, one slot per agent.

All agents of all swarms share one policy (parameter sharing): slot ``b·N + i`` is agent
i of swarm b, with that agent's local observation, action and the swarm's cooperative
reward. All swarms step in one array call on the batched core; no Python loop over
envs or agents (SuperSuit's ``pettingzoo_env_to_vec_env_v1`` + ``concat_vec_envs``
would loop, and never sets ``TimeLimit.truncated``).

A swarm whose episode ends is reset on its own within the same ``step_wait``. Its
slots' infos carry ``terminal_observation`` (the last observation of that episode) and
``TimeLimit.truncated`` (true when it ended by the step limit, not by success), which
SB3 uses to bootstrap the value of truncated episodes, and ``episode``: ``{"r": return,
"l": length, "t": seconds since the VecEnv was made}``, what SB3's ``VecMonitor`` would
add (so none is needed: its Python loop over the infos of every slot would cost more
than the batched step; wrapping one anyway gives the same values). So
``env_is_wrapped(Monitor)`` is true: SB3's ``evaluate_policy`` and ``EvalCallback`` read
the ``episode`` infos without a Monitor warning. ``swarm_episode`` is the same dict
under its older name.

Infos: the swarm's statistics (:data:`swarm_envs.envs.task.STAT_KEYS`) are in the info
of the swarm's first slot (``b·N``) only, as a
:class:`~swarm_envs.envs.adapters.vec_infos.SwarmInfo`; the slots of a swarm that just
ended get :class:`~swarm_envs.envs.adapters.vec_infos.TerminalInfo` infos (with the
statistics in the first); every other slot's info is an empty
:class:`~swarm_envs.envs.adapters.vec_infos.QuietInfo`. All are ``dict`` subclasses
(``json.dumps`` takes them; their values are read from the step's arrays on access),
writable (a write to a statistics or terminal info copies its values into the dict
itself). None of them is built per step: fresh dicts for 32k slots would cost more than
the fused step (see :mod:`swarm_envs.envs.adapters.vec_infos`). Copies of them
(``copy.copy``, ``copy.deepcopy``, pickling) are plain dicts, and the list
(:class:`~swarm_envs.envs.adapters.vec_infos.InfoList`) deep-copies and pickles as a
plain list with a dict of its own per slot.
:attr:`SwarmNavVecEnv.last_stats` holds the statistics as ``(B,)`` arrays.

The step runs on the backend ``auto`` picks (``backend=`` overrides; see
:mod:`swarm_envs.envs.backends`): by default the C step, which spreads the swarms over
its own threads; the dense numpy core for the other models; the cut-off core for large
swarms; the torch core on a GPU (``device="cuda"``). :attr:`SwarmNavVecEnv.backend`
says which. On the numpy backends large batches are split over worker threads
(``n_threads``; default one per 512 swarms, up to the CPU count), each stepping its own
slice of swarms on its own core: numpy releases the GIL inside its array loops, so the
slices run in parallel. A seed gives the same rollout for the same ``n_threads``.

The state is float32 by default (``dtype=np.float64`` for exact agreement with the
float64 single-swarm envs); observations are float32 either way.

Inputs follow the rule of ``docs/inputs.md``, as in the other APIs: ``step_async``
takes a real numeric array (float or integer dtype) of exactly ``(num_envs, d)``, a
list of numbers that converts to it, or a ``torch.Tensor`` (detached; on the torch
backend it stays on its device); bool, complex, object or string dtypes, another
shape (a transposed or flat array included) and NaN/inf raise ``ValueError``; finite
values are clipped to [−1, 1]. :meth:`SwarmNavVecEnv.seed` takes ``None`` or a
non-negative integer (Python or numpy).
"""

from __future__ import annotations

import dataclasses
import itertools
import os
import time
import warnings
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices

from swarm_envs.envs.adapters.inputs import (
    as_action,
    check_seed,
    check_tensor_action,
    is_tensor,
    make_config,
)
from swarm_envs.envs.adapters.vec_infos import (
    InfoList,
    QuietInfos,
    SwarmInfoPool,
    TerminalInfoPool,
    TerminalRecord,
)
from swarm_envs.envs.backends import make_core, resolve_backend
from swarm_envs.envs.common import check_dtype
from swarm_envs.envs.protocol import Core
from swarm_envs.envs.task import OBS_BOUND
from swarm_envs.envs.task.agent_status import ACTIVE


class SlotEpisodesWarning(UserWarning):
    """SB3's episode helpers count agents, not swarms, on :class:`SwarmNavVecEnv`."""

    def __init__(self, n_agents: int) -> None:
        super().__init__(
            f"SwarmNavVecEnv: every slot is one agent, so SB3's evaluate_policy, "
            f"EvalCallback and VecMonitor count one episode per agent: n_eval_episodes="
            f"{n_agents} is a single swarm episode of {n_agents} agents, which share "
            "its return (its std is then 0). Ask for n_swarms x n_agents x K episodes for "
            "K per swarm, or evaluate per swarm with swarm-eval (train.evaluate."
            "evaluate_policies)"
        )


class SwarmNavVecEnv(VecEnv):
    """``n_swarms`` SwarmNav swarms as one SB3 VecEnv with ``n_swarms × n_agents`` slots."""

    def __init__(
        self,
        n_swarms: int,
        config: str | None = None,
        render_mode: str | None = None,
        dtype: type = np.float32,
        n_threads: int | None = None,
        **kwargs: Any,
    ) -> None:
        if isinstance(n_swarms, bool) or not isinstance(n_swarms, (int, np.integer)):
            raise ValueError(f"n_swarms must be an integer >= 1, got {n_swarms!r}")
        if n_swarms < 1:
            raise ValueError(f"n_swarms must be an integer >= 1, got {n_swarms!r}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(
                f"vec_env render_mode must be None or 'rgb_array', got {render_mode!r}"
            )
        self.cfg = make_config(
            config,
            kwargs,
            owner="vec_env",
            keywords=("n_swarms", "config", "render_mode", "dtype", "n_threads"),
        )
        self.n_swarms = int(n_swarms)
        self.n_agents = self.cfg.n_agents
        self._warned_slot_episodes = False  # SlotEpisodesWarning given
        check_dtype(dtype)
        self.backend = resolve_backend(self.cfg, self.n_swarms)
        if self.backend in ("torch", "native"):  # one step for every swarm, threaded inside
            if n_threads not in (None, 1):
                raise ValueError(
                    f"n_threads must be null or 1 with the {self.backend} backend, "
                    f"got {n_threads!r}"
                )
            n_threads = 1
        self.n_threads = self._check_threads(n_threads)
        bounds = np.linspace(0, self.n_swarms, self.n_threads + 1).round().astype(int)
        self._slices = [slice(int(lo), int(hi)) for lo, hi in itertools.pairwise(bounds)]
        cfg = dataclasses.replace(self.cfg, backend=self.backend)  # the same for each slice
        self.cores = [make_core(cfg, batch=sl.stop - sl.start, dtype=dtype) for sl in self._slices]
        self._pool: ThreadPoolExecutor | None = None
        obs_space = spaces.Box(-OBS_BOUND, OBS_BOUND, (self.cores[0].obs_dim,), np.float32)
        act_space = spaces.Box(-1.0, 1.0, (self.cfg.dim,), np.float32)
        self.render_mode = render_mode  # before VecEnv.__init__, which reads it via get_attr
        super().__init__(self.n_swarms * self.n_agents, obs_space, act_space)
        self._rng = np.random.default_rng()
        self._actions: np.ndarray | None = None
        self.last_stats: dict[str, np.ndarray] = {}
        self.episode_returns = np.zeros(self.n_swarms)
        self.episode_lengths = np.zeros(self.n_swarms, np.int64)
        self._swarm_infos = SwarmInfoPool(self.n_swarms)
        self._terminal_infos = TerminalInfoPool(self.n_swarms, self.n_agents)
        self._quiet_infos = QuietInfos(self.num_envs)  # each step's list, recycled
        self._t_start = time.time()  # the "t" of the episode infos, as VecMonitor's
        #: Which slots' agents act ``(B, N)``; ``None`` while every agent always does.
        self._active: np.ndarray | None = None

    def _check_threads(self, n_threads: int | None) -> int:
        """Worker threads: given, or 1 per 512 swarms up to the CPU count (at least 1)."""
        if n_threads is None:
            return max(1, min(os.cpu_count() or 1, self.n_swarms // 512))
        if isinstance(n_threads, bool) or not isinstance(n_threads, (int, np.integer)):
            raise ValueError(
                f"n_threads must be null or an integer in [1, n_swarms], got {n_threads!r}"
            )
        if not 1 <= n_threads <= self.n_swarms:
            raise ValueError(
                f"n_threads must be in [1, {self.n_swarms}] (n_swarms), got {n_threads}"
            )
        return int(n_threads)

    @property
    def core(self) -> Core:
        """The single core (``n_threads == 1``); with several threads use :attr:`cores`."""
        if len(self.cores) != 1:
            raise AttributeError(f"this vec_env runs {len(self.cores)} cores; use .cores")
        return self.cores[0]

    def _map(self, fn: Callable[[Core, slice], Any]) -> list[Any]:
        """``fn(core, swarm_slice)`` for every core: in worker threads when there are several.

        numpy releases the GIL inside its array loops, so the cores' steps overlap.
        """
        if len(self.cores) == 1:
            return [fn(self.cores[0], self._slices[0])]
        if self._pool is None:
            self._pool = ThreadPoolExecutor(len(self.cores), thread_name_prefix="swarm_nav")
        return list(self._pool.map(fn, self.cores, self._slices))

    def _observe(self) -> np.ndarray:
        parts = self._map(lambda core, _: core.observe())
        return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=0)

    def _stats(self) -> dict[str, np.ndarray]:
        parts = [core.stats() for core in self.cores]
        return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_pool"] = None  # threads do not pickle; recreated on first use
        return state  # the info pools pickle as their sizes (see vec_infos.py)

    # ------------------------------------------------------------------ VecEnv API
    def reset(self) -> np.ndarray:
        """Reset every swarm. Uses the seed of :meth:`seed` once, if one was set.

        Starts are drawn core after core from one generator, so a seed gives the same
        swarms for the same ``n_threads``.
        """
        seed = self._seeds[0]
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self._reset_seeds()
        for core in self.cores:
            core.reset(self._rng)
        self.episode_returns[:] = 0.0
        self.episode_lengths[:] = 0
        self.last_stats = self._stats()
        self.reset_infos = [{} for _ in range(self.num_envs)]
        obs = self._observe()
        self._active = self._statuses()
        if self._active is not None:
            obs[~self._active] = 0.0
        return obs.reshape(self.num_envs, -1)

    def _statuses(self) -> np.ndarray | None:
        """Which agents act now ``(B, N)`` (``None``: the cores have no statuses)."""
        parts = []
        for core in self.cores:
            status = getattr(core, "status", None)
            if status is None:  # every core alike: one config
                return None
            parts.append(status)
        return np.concatenate(parts, axis=0) == ACTIVE

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Seed the next :meth:`reset`: ``None`` or a non-negative integer (Python or
        numpy; ``np.int64(3)`` seeds as ``3``), else :class:`ValueError`."""
        return super().seed(check_seed(seed))

    def step_async(self, actions: Any) -> None:
        """Check ``actions`` against the input rule (``(num_envs, d)``, real numeric;
        ``docs/inputs.md``) and keep them for :meth:`step_wait`; the core refuses
        NaN/inf there, before any swarm moves."""
        self._actions = None
        shape = (self.num_envs, self.cfg.dim)
        if is_tensor(actions) and self.backend == "torch":
            self._actions = check_tensor_action(actions, shape)  # stays on its device
        else:
            self._actions = as_action(actions, shape)

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict]]:
        if self._actions is None:
            raise RuntimeError("step_wait() called without step_async()")
        B, N, d = self.n_swarms, self.n_agents, self.cfg.dim
        actions, self._actions = self._actions, None
        a = actions.reshape(B, N, d)

        def step(core: Core, sl: slice) -> tuple:
            reward, terminated, truncated, stats = core.step(a[sl])
            # A core with swarms to reset observes after the reset, in step_wait.
            ended = terminated.any() or truncated.any()
            return reward, terminated, truncated, stats, None if ended else core.observe()

        parts = self._map(step)
        if len(parts) == 1:  # one core: its arrays as they are, no copies
            reward, terminated, truncated, stats, _ = parts[0]
        else:
            reward, terminated, truncated = (
                np.concatenate([p[i] for p in parts]) for i in range(3)
            )
            stats = {k: np.concatenate([p[3][k] for p in parts]) for k in parts[0][3]}
        self.last_stats = stats
        self.episode_returns += reward
        self.episode_lengths += 1
        done = terminated | truncated
        # Every slot's quiet info, the first slot of each swarm its SwarmInfo (vec_infos.py).
        infos = self._quiet_infos.infos()
        infos.put(slice(None, None, N), self._swarm_infos.infos(stats))  # read on access
        was_active = self._active
        if done.any():
            self._end_episodes(done, truncated & ~terminated, stats, infos, was_active)
        obs_parts = [
            core.observe() if p[4] is None else p[4]
            for core, p in zip(self.cores, parts, strict=True)
        ]
        obs = obs_parts[0] if len(obs_parts) == 1 else np.concatenate(obs_parts, axis=0)
        rewards = np.repeat(reward.astype(np.float32), N)
        dones = np.repeat(done, N)
        if was_active is not None:
            self._inactive_slots(obs, rewards, dones, infos, done, was_active)
        return obs.reshape(self.num_envs, -1), rewards, dones, infos

    def _inactive_slots(
        self,
        obs: np.ndarray,
        rewards: np.ndarray,
        dones: np.ndarray,
        infos: InfoList,
        done: np.ndarray,
        was_active: np.ndarray,
    ) -> None:
        """The slots of agents that do not act (failed, removed, absent, not yet joined).

        Such a slot's own episode ends when its agent stops acting: that step is done,
        with its last observation as ``terminal_observation``. From then on, every step
        of the slot is a one-step episode that ends at once: observation all zeros,
        reward 0, done, ``terminal_observation`` zeros, ``TimeLimit.truncated`` false
        (an absorbing state of value 0 for PPO's and SAC's targets). A joining agent's
        slot starts a new episode with its first real observation. These slots report
        no ``episode`` info: only the swarm's episode is counted.
        """
        N = self.n_agents
        active = self._statuses()
        assert active is not None
        self._active = active
        going = ~done[:, None]
        stopped = going & was_active & ~active  # its last step as an acting agent
        idle = ~was_active  # it did not act in this step
        # The idle slots of swarms that go on: the same absorbing transition, each in a
        # dict of its own (a C-level copy), sharing one read-only zero observation
        # (SB3's wrappers replace it rather than write into it).
        zeros = np.zeros(obs.shape[-1], obs.dtype)
        zeros.flags.writeable = False
        absorbing = {"terminal_observation": zeros, "TimeLimit.truncated": False}
        for slot in np.flatnonzero((going & idle & ~stopped).reshape(-1)).tolist():
            infos.put(slot, absorbing.copy() if slot % N else {**infos[slot], **absorbing})
        for b, i in zip(*np.nonzero(stopped), strict=True):
            slot = int(b) * N + int(i)
            last = {"terminal_observation": obs[b, i].copy(), "TimeLimit.truncated": False}
            infos.put(slot, {**infos[slot], **last})
        rewards[idle.reshape(-1)] = 0.0
        dones[(stopped | (going & idle)).reshape(-1)] = True
        obs[~active] = 0.0

    def _end_episodes(
        self,
        done: np.ndarray,
        time_limit: np.ndarray,
        stats: dict[str, np.ndarray],
        infos: InfoList,
        was_active: np.ndarray | None = None,
    ) -> None:
        """Terminal infos for the swarms ``done`` (into ``infos``), then reset them.

        Their last observations are copied out first (only their rows), so that each
        core's reset writes the new rows in place of the old ones; a slot whose agent
        did not act in the step ends with the zero observation.
        """
        N = self.n_agents
        ended = np.flatnonzero(done)  # only the swarms that just ended
        swarms = ended.tolist()
        cores = self._cores_with(done)
        last = [core.observe(which=done[sl]) for core, sl in cores]
        if was_active is not None:
            last = [
                np.where(was_active[sl][done[sl]][..., None], rows, 0.0).astype(rows.dtype)
                for rows, (_, sl) in zip(last, cores, strict=True)
            ]
        now = round(time.time() - self._t_start, 6)
        record = TerminalRecord(
            obs=dict(zip(swarms, itertools.chain.from_iterable(last), strict=True)),
            stats=stats,
            time_limit=time_limit,
            episodes={
                b: {"r": r, "l": n, "t": now}
                for b, r, n in zip(
                    swarms,
                    self.episode_returns[ended].tolist(),
                    self.episode_lengths[ended].tolist(),
                    strict=True,
                )
            },
        )
        terminal = self._terminal_infos.infos(record, swarms)
        for b in swarms:
            infos.put(slice(b * N, (b + 1) * N), terminal[b])
        for core, sl in cores:  # in order: seeded
            core.reset(self._rng, which=done[sl])
        self.episode_returns[done] = 0.0
        self.episode_lengths[done] = 0

    def _cores_with(self, done: np.ndarray) -> list[tuple[Core, slice]]:
        """The cores (with their slices) that step at least one swarm of ``done``."""
        return [
            (core, sl) for core, sl in zip(self.cores, self._slices, strict=True) if done[sl].any()
        ]

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    def get_images(self) -> Sequence[np.ndarray | None]:
        from swarm_envs.render import draw_swarm

        return [
            draw_swarm(
                core.x[b],
                goal=core.goal[b],
                goal_radius=self.cfg.arrival_radius,
                velocities=core.v[b],
            )
            for core in self.cores
            for b in range(core.batch)
        ]

    # ------------------------------------------------------------------ attributes
    def _indices(self, indices: VecEnvIndices) -> Iterable[int]:
        return self._get_indices(indices)

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        value = getattr(self, attr_name)
        return [value for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        raise ValueError(
            f"set_attr({attr_name!r}) is not supported: every slot shares one batched core"
        )

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **kwargs: Any
    ) -> list[Any]:
        method = getattr(self, method_name)
        return [method(*method_args, **kwargs) for _ in self._indices(indices)]

    def env_is_wrapped(
        self, wrapper_class: type[gymnasium.Wrapper], indices: VecEnvIndices = None
    ) -> list[bool]:
        """Whether each slot is wrapped in ``wrapper_class``: true for SB3's ``Monitor``
        alone, whose ``episode`` info every slot reports (``{"r", "l", "t"}`` at the end
        of its episode, as ``Monitor`` would), so that SB3's ``evaluate_policy`` and
        ``EvalCallback`` read it instead of warning; false for any other wrapper.

        SB3's helpers ask this before they count episodes, and they count one per slot
        that ends, i.e. per agent: the first time ``Monitor`` is asked about, a
        :class:`SlotEpisodesWarning` says so (once per VecEnv)."""
        wrapped = wrapper_class is Monitor
        if wrapped and not getattr(self, "_warned_slot_episodes", False):
            self._warned_slot_episodes = True
            warnings.warn(SlotEpisodesWarning(self.n_agents), stacklevel=2)
        return [wrapped for _ in self._indices(indices)]
