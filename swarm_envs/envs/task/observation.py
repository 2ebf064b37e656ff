"""The SwarmNav observation of each agent: its layout and features, defined once.

Per agent i, in this order (``d`` the dimension, ``k = n_neighbors``):

========================================  ====================================
features                                  size
========================================  ====================================
goal offset ``(r_g − r_i) / obs_goal_scale``                   ``d``
  (zeros for an agent not informed, ``task="informed"``)
own velocity ``v_i / obs_velocity_scale``                      ``d``
with ``task="informed"``: 1 if the agent is informed, else 0   ``1``
for each of the k nearest neighbours j, nearest first:
  offset ``(r_j − r_i) / obs_neighbor_scale``                  ``d``
  relative velocity ``(v_j − v_i) / obs_velocity_scale``       ``d``
  mask: 1 for a real neighbour, 0 for a padding slot           ``1``
  with ``observe_status``: 1 if that neighbour is active, 0      ``1``
  if it has failed (:mod:`~swarm_envs.envs.task.agent_status`)
  with ``task="informed"``: 1 if that neighbour is informed      ``1``
========================================  ====================================

"Nearest first" orders by ``(ρ_ij, j)``: equal distances by the lower index. When
``N − 1 < k`` the last ``k − (N − 1)`` slots are padding (all zeros). Every entry is
clipped to ``[−OBS_BOUND, OBS_BOUND]``; observations are float32 whatever the state's
dtype. Only agents present in the physics are neighbours: a slot whose ranked agent is
absent (fewer present others than ``k``) is padding, and an agent not present has no
neighbours (every slot padding). An agent's own features do not say
whether it has failed: a failed agent no longer acts, and the adapters stop asking it.
:func:`observation` computes this from the state and each agent's neighbour indices, on
numpy arrays or torch tensors; the C step writes the same layout.
"""

from __future__ import annotations

from typing import Any

from swarm_envs._array import ArrayNamespace
from swarm_envs.envs.task.agent_status import ACTIVE, FROZEN

Array = Any

#: Every observation component is clipped into ``[−OBS_BOUND, OBS_BOUND]``.
OBS_BOUND = 10.0

#: The layout of the module docstring in one line: the agent's own features, then each
#: neighbour block's (a backend that writes observations itself declares the layout it
#: writes, and is refused when it is not this one).
LAYOUT = (
    "goal_offset/obs_goal_scale,velocity/obs_velocity_scale;"
    "offset/obs_neighbor_scale,relative_velocity/obs_velocity_scale,mask"
)


def _informs(task: Any) -> bool:
    return bool(getattr(task, "informs_agents", False))


def own_size(task: Any) -> int:
    """Entries of the agent's own features: ``2d`` (goal offset, velocity), one more
    (its informed flag) with ``task="informed"``."""
    return 2 * task.dim + int(_informs(task))


def block_size(task: Any) -> int:
    """Entries per neighbour slot: ``2d + 1`` (offset, velocity, mask), one more with
    ``observe_status``, one more with ``task="informed"``."""
    return 2 * task.dim + 1 + int(getattr(task, "observe_status", False)) + int(_informs(task))


def observation_size(task: Any) -> int:
    """``own + k · block``: the agent's own features (:func:`own_size`), then k
    neighbour slots (:func:`block_size`)."""
    return own_size(task) + task.n_neighbors * block_size(task)


def layout(task: Any) -> str:
    """:data:`LAYOUT`, with ``,status`` ending each neighbour block under
    ``observe_status`` and the informed flags with ``task="informed"``."""
    out = LAYOUT + (",status" if getattr(task, "observe_status", False) else "")
    if _informs(task):
        own, block = out.split(";")
        out = f"{own},informed;{block},informed"
    return out


def ranked_neighbors(task: Any) -> int:
    """How many nearest neighbours a core ranks: ``min(max(k, 1), N − 1)`` (at least
    one, for the nearest-neighbour distance; 0 when ``N = 1``)."""
    return min(max(task.n_neighbors, 1), task.n_agents - 1)


def observation(
    x: Array,
    v: Array,
    goal: Array,
    near: Array | None,
    task: Any,
    xp: ArrayNamespace,
    status: Array | None = None,
    informed: Array | None = None,
) -> Array:
    """Observations ``(B, N, obs_dim)`` float32 (the layout of the module docstring).

    Args:
        x, v: positions and velocities ``(B, N, d)``.
        goal: goals ``(B, d)``.
        near: each agent's neighbour indices, nearest first, ``(B, N, k')`` with
            ``k' ≥ min(k, N − 1)`` (only the first ``min(k, N − 1)`` are read), or
            ``None`` when no neighbour is observed.
        task: the :class:`~swarm_envs.config.SwarmConfig`.
        xp: the array namespace of ``x``.
        status: each agent's status ``(B, N)`` (``None``: every agent active); the
            neighbour ranking must put agents not present last.
        informed: which agents observe the goal ``(B, N)`` bool, required with
            ``task="informed"`` (and read only then).
    """
    B, N, d = x.shape
    k = task.n_neighbors
    k_real = min(k, N - 1)
    block = block_size(task)
    goal_offset = (goal[:, None, :] - x) / task.obs_goal_scale
    told = None
    if _informs(task):
        if informed is None:
            raise ValueError("task='informed' needs each agent's informed flag")
        told = xp.astype(informed, x)
        goal_offset = goal_offset * told[..., None]
    parts = [goal_offset, v / task.obs_velocity_scale]
    if told is not None:
        parts.append(told[..., None])
    if k_real > 0:
        assert near is not None
        # One neighbour feature at a time: gather the column of every agent's values
        # for its neighbours, subtract the agent's own value, scale; then interleave the
        # features into blocks (offset, relative velocity, mask) per neighbour.
        index = near[..., :k_real]
        columns = [x[..., c] for c in range(d)] + [v[..., c] for c in range(d)]
        scales = [1.0 / task.obs_neighbor_scale] * d + [1.0 / task.obs_velocity_scale] * d
        flag_columns = []
        if status is not None:  # present, active, and each agent's own index
            present = xp.astype(status <= FROZEN, x)
            ids = xp.zeros((B, N), like=x) + xp.array(list(range(N)), like=x)
            flag_columns = [present, xp.astype(status == ACTIVE, x), ids]
        if told is not None:
            flag_columns.append(told)
        gathered = xp.gather_agents(columns + flag_columns, index)
        flags = gathered[2 * d :]
        gathered = gathered[: 2 * d]
        told_slots = flags.pop() if told is not None else None
        features = [
            (g - col[..., None]) * scale
            for g, col, scale in zip(gathered, columns, scales, strict=True)
        ]
        if status is None:
            features.append(xp.ones((B, N, k_real), like=x))
        else:
            # A slot holds a neighbour where both are present and it is another agent
            # (the ranking puts the others not present, and the agent itself, last).
            real, active, slot_ids = flags
            real = real * present[..., None] * xp.astype(slot_ids != ids[..., None], x)
            features = [f * real for f in features] + [real]
        if getattr(task, "observe_status", False):
            features.append(xp.ones((B, N, k_real), like=x) if status is None else active * real)
        if told_slots is not None:
            features.append(told_slots if status is None else told_slots * real)
        parts.append(xp.stack(features, axis=-1).reshape(B, N, k_real * block))
    if k > k_real:
        parts.append(xp.zeros((B, N, (k - k_real) * block), like=x))
    obs = xp.concat(parts, axis=-1)
    return xp.float32(xp.clip(obs, -OBS_BOUND, OBS_BOUND))
