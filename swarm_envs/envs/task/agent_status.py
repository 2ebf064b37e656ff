"""Which agents take part, defined once: each agent's status, its masks, and the
episode's draws of failures, joins and noise (``SwarmConfig.perturbations``).

An agent is in one of four states:

==========  ===========  ==========  ==========  =======================================
status      acts         moves       in physics  what it is
==========  ===========  ==========  ==========  =======================================
``ACTIVE``  yes          yes         yes         a working agent
``FAILED``  no           yes         yes         failed, ``failure_mode="passive"``: its
                                                 passive physics goes on, its action is
                                                 ignored
``FROZEN``  no           no          yes         failed, ``"frozen"``: at rest where it
                                                 failed, still a source of pair forces
``ABSENT``  no           no          no          failed ``"removed"``, absent for the
                                                 episode, or not yet joined
==========  ===========  ==========  ==========  =======================================

The masks follow (:func:`masks`): ``controlled`` (acts), ``mobile`` (its update is
integrated; the others keep their position at zero velocity) and ``present`` (a pair
with an agent not present has no interaction: no force, no rate, no collision, not a
neighbour). The group statistics and the task (arrival, success) count the **members**,
the mobile agents: a frozen or absent agent cannot reach the goal, a passive one must be
brought along. The statuses at a time follow from the episode's draws
(:class:`AgentSchedule`); cores receive them and apply the masks, adapters read them
to tell which agents act.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from swarm_envs.perturbations import Perturbations, agent_count

ACTIVE, FAILED, FROZEN, ABSENT = 0, 1, 2, 3

#: A step index no episode reaches (an agent that never fails).
NEVER = np.iinfo(np.int64).max

_FAILED_STATUS = {"passive": FAILED, "frozen": FROZEN, "removed": ABSENT}


class AgentMasks(NamedTuple):
    """Boolean masks ``(B, N)`` of a status array (numpy or torch)."""

    controlled: Any
    mobile: Any
    present: Any


def masks(status: Any) -> AgentMasks:
    """The masks of ``status`` ``(B, N)`` (the table of the module docstring)."""
    return AgentMasks(status == ACTIVE, status <= FAILED, status <= FROZEN)


def all_active(batch: int, n_agents: int) -> np.ndarray:
    """Every agent active: ``(B, N)`` int8 zeros."""
    return np.zeros((batch, n_agents), dtype=np.int8)


def _draw(rng: np.random.Generator, bounds: tuple[Any, Any], size: int, integer: bool) -> Any:
    """``size`` values from ``bounds``: the value itself when ``low == high`` (no draw)."""
    low, high = bounds
    if low == high:
        return np.full(size, low)
    if integer:
        return rng.integers(low, high + 1, size=size)
    return rng.uniform(low, high, size=size)


class AgentSchedule:
    """The perturbations drawn for each of ``batch`` swarms: who fails or joins when,
    who is absent, and each swarm's noise levels.

    Arrays ``(B, N)``: ``fail_at`` (the step after which an agent has failed; ``NEVER``
    if it does not), ``join_at`` (the step after which it is present; 0 from the start),
    ``absent`` (absent for the episode); ``(B,)``: ``obs_noise``, ``action_noise``,
    ``neighbor_dropout``.
    """

    def __init__(self, p: Perturbations, batch: int, n_agents: int) -> None:
        self.p = p
        self.batch, self.n_agents = batch, n_agents
        self.fail_at = np.full((batch, n_agents), NEVER, dtype=np.int64)
        self.join_at = np.zeros((batch, n_agents), dtype=np.int64)
        self.absent = np.zeros((batch, n_agents), dtype=bool)
        self.obs_noise = np.zeros(batch)
        self.action_noise = np.zeros(batch)
        self.neighbor_dropout = np.zeros(batch)

    def draw(self, rng: np.random.Generator, idx: np.ndarray) -> None:
        """New draws for the swarms ``idx`` (after their starts), from ``rng``.

        Per swarm, in this order: the absent, joining and failing counts
        (``⌊fraction · N⌋`` of each fraction drawn from its range), one permutation of
        the agents (absent first, then joining, then failing), each joining and failing
        agent's step, then the noise levels. Fixed values draw nothing.
        """
        p, n = self.p, self.n_agents
        for b in idx:
            counts = [
                agent_count(float(_draw(rng, p.bounds(name), 1, False)[0]), n)
                for name in ("absent_fraction", "join_fraction", "failed_fraction")
            ]
            n_absent, n_join, n_fail = counts
            self.fail_at[b] = NEVER
            self.join_at[b] = 0
            self.absent[b] = False
            if n_absent + n_join + n_fail == 0:
                continue
            order = rng.permutation(n)
            self.absent[b, order[:n_absent]] = True
            joining = order[n_absent : n_absent + n_join]
            failing = order[n_absent + n_join : n_absent + n_join + n_fail]
            self.join_at[b, joining] = _draw(rng, p.bounds("join_time"), n_join, True)
            self.fail_at[b, failing] = _draw(rng, p.bounds("failure_time"), n_fail, True)
        for name in ("obs_noise", "action_noise", "neighbor_dropout"):
            getattr(self, name)[idx] = _draw(rng, p.bounds(name), idx.size, False)

    def status(self, t: np.ndarray) -> np.ndarray:
        """Every agent's status ``(B, N)`` int8 after ``t`` ``(B,)`` steps."""
        t = np.asarray(t)[:, None]
        status = np.where(t >= self.fail_at, _FAILED_STATUS[self.p.failure_mode], ACTIVE)
        status = np.where(self.absent | (t < self.join_at), ABSENT, status)
        return status.astype(np.int8)


def perturb_actions(
    a: np.ndarray, status: np.ndarray, sigma: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """The actions the agents apply: ``clip(a + σ ξ, −1, 1)`` per swarm's ``σ`` (no draw
    where every ``σ`` is 0), then zero for every agent that does not act."""
    if np.any(sigma > 0):
        noise = rng.standard_normal(a.shape) * sigma[:, None, None]
        a = np.clip(a + noise.astype(a.dtype, copy=False), -1.0, 1.0)
    return np.where((status == ACTIVE)[..., None], a, 0.0).astype(a.dtype, copy=False)


def perturb_observations(
    obs: np.ndarray,
    *,
    dim: int,
    block: int,
    n_slots: int,
    sigma: np.ndarray,
    dropout: np.ndarray,
    rng: np.random.Generator,
    bound: float,
    own: int | None = None,
) -> np.ndarray:
    """Observations ``(B, N, D)`` with neighbour slots dropped and noise added.

    The agent's own features come first (``own`` entries, ``2d`` if not given), then
    the ``n_slots`` neighbour blocks (``block`` entries: offset, relative velocity, slot
    mask, then the flags observed). Each block is dropped with its swarm's probability:
    all zeros, as padding reads. Gaussian noise of the swarm's ``σ`` is then added to the
    goal offset and velocity (the first ``2d``) and to the offsets and relative
    velocities of the slots that hold a neighbour, never to the flags, and the result
    clipped to ``±bound``. Draws: the dropout's uniforms (if any swarm drops), then the
    noise's normals (if any swarm is noisy).
    """
    out = obs.copy()
    B, N, _ = out.shape
    own = 2 * dim if own is None else own
    slots = out[..., own : own + n_slots * block].reshape(B, N, n_slots, block)
    if n_slots and np.any(dropout > 0):
        drop = rng.random((B, N, n_slots)) < dropout[:, None, None]
        slots[drop] = 0.0
    if np.any(sigma > 0):
        noise = (rng.standard_normal(out.shape) * sigma[:, None, None]).astype(np.float32)
        out[..., : 2 * dim] += noise[..., : 2 * dim]
        if n_slots:
            real = slots[..., 2 * dim : 2 * dim + 1] > 0  # the slot mask
            slot_noise = noise[..., own : own + n_slots * block].reshape(B, N, n_slots, block)
            slots[..., : 2 * dim] += np.where(real, slot_noise[..., : 2 * dim], 0.0)
        np.clip(out, -bound, bound, out=out)
    return out


class StatusUpdate(NamedTuple):
    """A checked ``set_status`` call: the statuses ``(B, N)`` int8, the agents to place
    ``(B, N)`` bool (or ``None``) and the swarms to measure again ``(B,)`` bool."""

    status: np.ndarray
    place: np.ndarray | None
    rows: np.ndarray


def status_update(
    old: np.ndarray | None,
    status: Any,
    place: Any,
    at: Any,
    rows: Any,
    shape: tuple[int, int, int],
) -> StatusUpdate:
    """The check of a ``set_status`` call (``protocol.StatusCore``, made by the task
    layer, :mod:`swarm_envs.envs.task.layer`): check the arguments against ``shape``
    ``(B, N, d)`` and find the swarms whose statuses or places change, or that ``rows``
    names (all of them when there were no statuses before).

    Raises:
        ValueError: ``status`` not ``(B, N)`` with values 0 to ``ABSENT``, or
            ``place``/``at`` not ``(B, N)`` bool and ``(B, N, d)``.
    """
    B, N, d = shape
    status = np.array(status, dtype=np.int8)
    if status.shape != (B, N) or status.min() < 0 or status.max() > ABSENT:
        raise ValueError(
            f"status must be ({B}, {N}) with values 0 to {ABSENT}, got shape {status.shape}"
        )
    changed = np.ones(B, dtype=bool) if old is None else (old != status).any(-1)
    remeasure = changed if rows is None else changed | np.asarray(rows, dtype=bool)
    if place is not None:
        place = np.asarray(place, dtype=bool)
        if place.shape != (B, N) or at is None or np.shape(at) != (B, N, d):
            raise ValueError(
                f"place must be ({B}, {N}) bool with at ({B}, {N}, {d}), got "
                f"{place.shape} and {None if at is None else np.shape(at)}"
            )
        remeasure = remeasure | place.any(axis=-1)
    return StatusUpdate(status, place, remeasure)


def keep_measured(
    stats: dict[str, np.ndarray],
    before: dict[str, np.ndarray],
    prev: dict[str, np.ndarray],
    start_stats: dict[str, np.ndarray],
    rows: np.ndarray,
    start: bool,
) -> None:
    """After a core measured its swarms again for new statuses: the swarms not in
    ``rows`` keep their statistics of ``before`` (an undone step's ``unstable`` flag
    included), and those in ``rows`` take the new ones as their previous statistics
    (``start=True``: as their episode's start too), in place."""
    idx = np.flatnonzero(rows)
    for key, value in stats.items():
        value[~rows] = before[key][~rows]
        prev[key][idx] = value[idx]
        if start:
            start_stats[key][idx] = value[idx]
