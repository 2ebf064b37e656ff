"""Seeded SwarmNav episodes of one policy, all stepped at once on one batched core.

:func:`run_episodes` runs ``B`` episodes on one core with ``batch = B``, made by
:func:`swarm_envs.envs.backends.make_core` from the config's ``backend`` and ``device``
(float64 state), and records them in an :class:`EpisodeBatch`: per-episode totals,
the group statistics at each episode's end, their curves over time, and episode 0's
trajectory (for the GIF). Once at most a quarter of the episodes are running, a numpy
core whose model allows it (:func:`~swarm_envs.envs.cores.numpy.keeps_rows`) shrinks to
their swarms, with the same results bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agents.base import swarm_config_of
from swarm_envs.config import SwarmConfig
from swarm_envs.envs.backends import make_core
from swarm_envs.envs.cores.numpy import keeps_rows, shrink_due
from swarm_envs.envs.perturbed import PerturbedCore
from swarm_envs.envs.task.agent_status import ACTIVE
from train.evaluate.policies import SpaceMismatchError, config_for_policy, policy_mode

__all__ = ["CURVE_KEYS", "FINAL_KEYS", "EpisodeBatch", "run_episodes"]

#: Statistics recorded at every step and plotted against time (mean over episodes).
CURVE_KEYS = ("centroid_distance", "expanse", "polarization", "angular_momentum")

#: Statistics reported at each episode's last step, as ``final_<key>``.
FINAL_KEYS = (
    "expanse",
    "polarization",
    "angular_momentum",
    "nearest_neighbor_distance",
    "centroid_distance",
    "fraction_arrived",
    "mill_order",
)


@dataclass
class EpisodeBatch:
    """Everything recorded for one policy over ``B`` episodes.

    Per-episode arrays are shaped ``(B,)``. ``curves`` maps each of :data:`CURVE_KEYS`
    to ``(T + 1, B)`` (index 0 is the start; an episode that has ended holds its last
    value); ``times`` is ``(T + 1,)`` in simulated seconds. ``trajectory`` holds episode
    0: positions and velocities ``(T0 + 1, N, d)`` and its goal ``(d,)``. ``backend``
    names the core that ran the episodes.

    Step-size control: ``unstable`` marks the episodes that ended on an unstable step
    (``info["unstable"] = 1``, truncated with ``on_unstable="truncate"``);
    ``substeps`` sums ``info["substeps"]`` over each episode's integrated steps and
    ``integrated`` counts those steps (an unstable step is undone, so not counted).

    Perturbations (``cfg.perturbations``): ``effort`` counts the actions of the agents
    that act in each step only (a failed, frozen, removed or absent agent's action is
    ignored by the core, so it costs nothing), still divided by ``N`` as the reward's
    effort term is.
    """

    name: str
    mode: str
    dt: float
    backend: str
    returns: np.ndarray
    success: np.ndarray
    lengths: np.ndarray
    collisions: np.ndarray
    effort: np.ndarray
    final: dict[str, np.ndarray]
    curves: dict[str, np.ndarray]
    times: np.ndarray
    unstable: np.ndarray
    substeps: np.ndarray
    integrated: np.ndarray
    trajectory: dict[str, np.ndarray] = field(default_factory=dict)
    start: dict[str, np.ndarray] = field(default_factory=dict)
    """Every episode's start state: positions and velocities ``(B, N, d)``, goals
    ``(B, d)`` and, for the zone model, each agent's turning limit ``max_turn`` ``(B, N)``
    (the same for every policy run on the same seed)."""
    first_success: np.ndarray | None = None
    """The step at which each episode first succeeded ``(B,)`` (0: never): its end in
    navigation, the first step of the held mill in the mill task (``None``: the
    episodes' lengths)."""


def run_episodes(
    policy: Any,
    cfg: SwarmConfig | Any,
    episodes: int,
    seed: int,
    *,
    name: str = "policy",
    deterministic: bool = True,
    progress: bool = False,
    record_episode: bool = True,
) -> EpisodeBatch:
    """Run ``episodes`` seeded episodes of ``policy`` at once on one batched core.

    Args:
        policy: an object with SB3's ``predict``.
        cfg: a :class:`SwarmConfig` (or any env it can be read from).
        episodes: number of episodes ``B ≥ 1`` (all stepped together).
        seed: seed of the start states (``numpy.random.default_rng(seed)``).
        name: label of the progress bar and of the result.
        deterministic: passed to ``predict``.
        progress: show a tqdm progress bar (on stderr).
        record_episode: keep episode 0's trajectory (for the GIF).

    Raises:
        SpaceMismatchError: see :func:`policy_mode`.
        ValueError: ``episodes < 1``, the policy returned non-finite actions, or the
            config's ``device`` is unavailable or needs another backend
            (:func:`~swarm_envs.envs.backends.make_core`).
        SwarmUnstableError: a step went unstable and the config's ``on_unstable`` is
            ``"raise"`` (with ``"truncate"`` that episode ends, marked ``unstable``).
    """
    cfg = swarm_config_of(cfg)
    if isinstance(episodes, bool) or int(episodes) != episodes or episodes < 1:
        raise ValueError(f"episodes must be an integer >= 1, got {episodes!r}")
    cfg = config_for_policy(policy, cfg)
    mode = policy_mode(policy, cfg)
    B, N, d = int(episodes), cfg.n_agents, cfg.dim
    core = make_core(cfg, batch=B)  # the config's backend and device
    core.reset(np.random.default_rng(seed))

    returns = np.zeros(B)
    lengths = np.zeros(B, np.int64)
    collisions = np.zeros(B)
    effort = np.zeros(B)
    success = np.zeros(B, bool)
    first_success = np.zeros(B, np.int64)
    unstable = np.zeros(B, bool)
    substeps = np.zeros(B)
    integrated = np.zeros(B, np.int64)
    done = np.zeros(B, bool)
    stats = core.stats()
    final = {k: stats[k].astype(np.float64) for k in FINAL_KEYS}
    series = {k: [stats[k].astype(np.float64)] for k in CURVE_KEYS}
    xs, vs = [core.x[0].copy()], [core.v[0].copy()]
    goal0 = core.goal[0].copy()
    start = {"x": np.array(core.x), "v": np.array(core.v), "goal": np.array(core.goal)}
    zone = getattr(getattr(core, "dynamics", None), "agent_params", None)
    if zone is not None:  # the zone model's per-agent turning limits, for the bound
        start["max_turn"] = np.array(zone.max_turn, np.float64)
    state: Any = None
    episode_start = np.ones(B, bool)

    from tqdm.auto import tqdm

    # Once few episodes are live (shrink_due), a core that can (the numpy core, on a
    # model that steps each swarm on its own state alone) shrinks to their swarms:
    # one stalled episode would keep every swarm stepping to max_steps. The policy still
    # sees the whole batch, the ended episodes' last inputs held, so that each live
    # episode's actions, and so the results, are those of the whole batch.
    keeper = core if keeps_rows(core) else None
    rows = np.arange(B)  # the episode of each of the core's rows
    held: np.ndarray | None = None  # every episode's policy input, once the core shrank
    inputs = np.empty(0)
    bar = tqdm(total=cfg.max_steps, desc=name, unit="step", disable=not progress, leave=True)
    try:
        for _ in range(cfg.max_steps):
            if keeper is not None and shrink_due(int((~done).sum()), len(rows)):
                if held is None:  # the last step's inputs, of the whole batch
                    held = np.array(inputs)
                keeper.keep(np.flatnonzero(~done[rows]))
                rows = np.flatnonzero(~done)
            inputs = _policy_input(core, mode, cfg.observe_status)
            if held is not None:
                held[rows] = inputs
                inputs = held
            if mode == "central":
                action, state = policy.predict(
                    inputs,
                    state=state,
                    episode_start=episode_start,
                    deterministic=deterministic,
                )
            else:
                action, state = policy.predict(
                    inputs.reshape(B * N, -1),
                    state=state,
                    episode_start=np.repeat(episode_start, N),
                    deterministic=deterministic,
                )
            episode_start = np.zeros(B, bool)
            a = np.asarray(action)
            if a.size != B * N * d:
                raise SpaceMismatchError(
                    f"policy {name!r} returned actions of shape {a.shape}; expected "
                    f"{(B * N, d) if mode == 'shared' else (B, N * d)}"
                )
            a = a.reshape(B, N, d)
            clipped = np.clip(a.astype(np.float64), -1.0, 1.0)
            if isinstance(core, PerturbedCore):  # the statuses before the step: who acts
                clipped = np.where((core.status == ACTIVE)[..., None], clipped, 0.0)
            if len(rows) < B:
                reward, terminated, truncated, stats = _scattered(core.step(a[rows]), rows, B)
            else:
                reward, terminated, truncated, stats = core.step(a)  # validates, clips
            live = ~done
            returns[live] += reward[live]
            lengths[live] += 1
            collisions[live] += stats["collisions"][live]
            effort[live] += np.einsum("bik,bik->b", clipped, clipped)[live] / N
            undone = np.asarray(stats["unstable"]) > 0
            counted = live & ~undone
            substeps[counted] += stats["substeps"][counted]
            integrated[counted] += 1
            for k in CURVE_KEYS:
                series[k].append(stats[k].astype(np.float64))
            ended = live & (terminated | truncated)
            # Success ends navigation (terminated); the mill task holds its state to the
            # end, so there success is the last step's.
            success |= ended & (terminated | ((stats["success"] > 0) & ~undone))
            first = live & ~undone & (stats["success"] > 0) & (first_success == 0)
            first_success[first] = lengths[first]
            unstable |= ended & undone
            for k in FINAL_KEYS:
                final[k][ended] = stats[k][ended]
            if record_episode and live[0]:
                xs.append(core.x[0].copy())
                vs.append(core.v[0].copy())
            done |= ended
            bar.update(1)
            if progress:
                bar.set_postfix(
                    done=f"{int(done.sum())}/{B}", success=int(success.sum()), refresh=False
                )
            if done.all():
                break
    finally:
        bar.close()

    # Hold each episode's last value after it ended.
    steps = np.arange(len(series[CURVE_KEYS[0]]))
    hold = np.minimum(steps[:, None], lengths[None, :])
    curves = {k: np.take_along_axis(np.stack(v), hold, axis=0) for k, v in series.items()}
    trajectory = {}
    if record_episode:
        trajectory = {"x": np.stack(xs), "v": np.stack(vs), "goal": goal0}
    return EpisodeBatch(
        name=name,
        mode=mode,
        dt=cfg.dt,
        backend=core.backend,
        returns=returns,
        success=success,
        lengths=lengths,
        collisions=collisions,
        effort=effort,
        final=final,
        curves=curves,
        times=steps * cfg.dt,
        unstable=unstable,
        substeps=substeps,
        integrated=integrated,
        trajectory=trajectory,
        start=start,
        first_success=first_success,
    )


def _policy_input(core: Any, mode: str, observe_status: bool) -> np.ndarray:
    """The policy's input for each of the core's ``R`` swarms: ``(R, N, obs_dim)``
    (shared), or the central env's flat observation ``(R, N·obs_dim [+ N])`` with every
    agent's status flag last where ``observe_status``."""
    obs = np.asarray(core.observe())
    if mode != "central":
        return obs
    R, N = obs.shape[:2]
    central = obs.reshape(R, -1)
    if observe_status:
        flags = (getattr(core, "status", np.zeros((R, N))) == ACTIVE).astype(np.float32)
        central = np.concatenate([central, flags], axis=1)
    return central


def _scattered(
    result: tuple[Any, Any, Any, dict[str, Any]], rows: np.ndarray, B: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """A step's ``(reward, terminated, truncated, stats)`` of a core shrunk to the
    episodes ``rows``, spread over all ``B`` episodes (the ended ones: zero, never read)."""

    def spread(values: Any) -> np.ndarray:
        values = np.asarray(values)
        out = np.zeros((B, *values.shape[1:]), values.dtype)
        out[rows] = values
        return out

    reward, terminated, truncated, stats = result
    return (
        spread(reward),
        spread(terminated),
        spread(truncated),
        {k: spread(v) for k, v in stats.items()},
    )
