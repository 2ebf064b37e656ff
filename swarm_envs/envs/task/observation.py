"""The SwarmNav observation of each agent: its layout and features, defined once.

Per agent i, in this order (``d`` the dimension, ``k = n_neighbors``):

========================================  ====================================
features                                  size
========================================  ====================================
goal offset ``(r_g − r_i) / obs_goal_scale``                   ``d``
  (zeros for an agent not informed, ``task="informed"``)
own velocity ``v_i / obs_velocity_scale``                      ``d``
the task's features (its spec's ``features``), in order:       their widths
  with ``task="informed"``: 1 if the agent is informed, else 0
for each of the k nearest neighbours j, nearest first:
  offset ``(r_j − r_i) / obs_neighbor_scale``                  ``d``
  relative velocity ``(v_j − v_i) / obs_velocity_scale``       ``d``
  mask: 1 for a real neighbour, 0 for a padding slot           ``1``
  with ``observe_status``: 1 if that neighbour is active, 0      ``1``
  if it has failed (:mod:`~swarm_envs.envs.task.agent_status`)
  the task's ``neighbors`` features of that neighbour          their widths
  (``task="informed"``: 1 if that neighbour is informed)
========================================  ====================================

"Nearest first" orders by ``(ρ_ij, j)``: equal distances by the lower index. When
``N − 1 < k`` the last ``k − (N − 1)`` slots are padding (all zeros). Every entry is
clipped to ``[−OBS_BOUND, OBS_BOUND]``; observations are float32 whatever the state's
dtype. Only agents present in the physics are neighbours: a slot whose ranked agent is
absent (fewer present others than ``k``) is padding, and an agent not present has no
neighbours (every slot padding). An agent's own features do not say
whether it has failed: a failed agent no longer acts, and the adapters stop asking it.
:func:`observation` computes this from the state and each agent's neighbour indices, on
numpy arrays or torch tensors; the C step writes the same layout (without task
features: it refuses a task that has them).

A task's feature (:class:`ObservationFeature`) is a function of :class:`FeatureInputs`
(the state, the goal, who are members and who is informed) over the array namespace,
so that every core computes it with this module.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NamedTuple

from swarm_envs._array import ArrayNamespace
from swarm_envs.envs.task.agent_status import ACTIVE, FAILED, FROZEN

if TYPE_CHECKING:
    from swarm_envs.config import SwarmConfig

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


class FeatureInputs(NamedTuple):
    """What an observation feature reads (numpy arrays or torch tensors).

    Attributes:
        x, v: positions and velocities ``(B, N, d)``.
        goal: goals ``(B, d)``.
        members: which agents are the swarm's members (the mobile ones) ``(B, N)`` bool;
            ``None``: every agent.
        informed: which agents observe the goal ``(B, N)`` bool (an ``informed`` task);
            else ``None``.
    """

    x: Any
    v: Any
    goal: Any
    members: Any | None
    informed: Any | None


@dataclass(frozen=True)
class ObservationFeature:
    """One per-agent observation feature of a task: ``value(inputs, cfg, xp)``, a
    ``(B, N)`` array (``width`` 1) or ``(B, N, width)``, in observation units (the whole
    observation is clipped to ``[−OBS_BOUND, OBS_BOUND]``).

    Attributes:
        name: its name in the layout (and in the conformance suite's messages).
        doc: what it is, one phrase.
        value: the feature of every agent, over ``xp`` (:mod:`swarm_envs._array`).
        width: entries per agent: a number, or ``width(cfg)`` (``lambda cfg: cfg.dim``
            for a vector).
        neighbors: whether each neighbour slot also holds that neighbour's value (zero
            in a padding slot).
    """

    name: str
    doc: str
    value: Callable[[FeatureInputs, SwarmConfig, ArrayNamespace], Array]
    width: int | Callable[[SwarmConfig], int] = 1
    neighbors: bool = False

    def size(self, task: SwarmConfig) -> int:
        """The entries per agent for config ``task``."""
        return int(self.width(task) if callable(self.width) else self.width)


#: The informed task's feature: whether the agent (and each neighbour) observes the goal.
INFORMED_FLAG = ObservationFeature(
    "informed",
    "1 if the agent observes the goal, else 0",
    lambda s, task, xp: xp.astype(s.informed, s.x),
    neighbors=True,
)


def _features(task: SwarmConfig) -> tuple[ObservationFeature, ...]:
    spec = getattr(task, "task_spec", None)
    return () if spec is None else spec.features


def _informs(task: SwarmConfig) -> bool:
    return bool(getattr(task, "informs_agents", False))


def own_size(task: SwarmConfig) -> int:
    """Entries of the agent's own features: ``2d`` (goal offset, velocity), then its
    task's features (one, its informed flag, with ``task="informed"``)."""
    return 2 * task.dim + sum(f.size(task) for f in _features(task))


def block_size(task: SwarmConfig) -> int:
    """Entries per neighbour slot: ``2d + 1`` (offset, velocity, mask), one more with
    ``observe_status``, then the task's ``neighbors`` features (one with
    ``task="informed"``)."""
    own = sum(f.size(task) for f in _features(task) if f.neighbors)
    return 2 * task.dim + 1 + int(getattr(task, "observe_status", False)) + own


def observation_size(task: SwarmConfig) -> int:
    """``own + k · block``: the agent's own features (:func:`own_size`), then k
    neighbour slots (:func:`block_size`)."""
    return own_size(task) + task.n_neighbors * block_size(task)


def layout(task: SwarmConfig) -> str:
    """:data:`LAYOUT`, with ``,status`` ending each neighbour block under
    ``observe_status``, and the task's features by name (the informed flags with
    ``task="informed"``)."""
    own, block = LAYOUT.split(";")
    block += ",status" if getattr(task, "observe_status", False) else ""
    for f in _features(task):
        own += f",{f.name}"
        block += f",{f.name}" if f.neighbors else ""
    return f"{own};{block}"


def ranked_neighbors(task: SwarmConfig) -> int:
    """How many nearest neighbours a core ranks: ``min(max(k, 1), N − 1)`` (at least
    one, for the nearest-neighbour distance; 0 when ``N = 1``)."""
    return min(max(task.n_neighbors, 1), task.n_agents - 1)


def observation(
    x: Array,
    v: Array,
    goal: Array,
    near: Array | None,
    task: SwarmConfig,
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
        informed: which agents observe the goal ``(B, N)`` bool, required by a task
            whose spec is ``informed`` (and read only then).
    """
    B, N, d = x.shape
    k = task.n_neighbors
    k_real = min(k, N - 1)
    block = block_size(task)
    goal_offset = (goal[:, None, :] - x) / task.obs_goal_scale
    if _informs(task):
        if informed is None:
            raise ValueError(f"task={task.task!r} needs each agent's informed flag")
        goal_offset = goal_offset * xp.astype(informed, x)[..., None]
    parts = [goal_offset, v / task.obs_velocity_scale]
    # The task's features, each (B, N, width); the neighbours' among them gathered below.
    shared: list[Any] = []
    features = _features(task)
    if features:
        members = None if status is None else status <= FAILED
        inputs = FeatureInputs(x, v, goal, members, informed)
        for f in features:
            value = f.value(inputs, task, xp)
            value = value[..., None] if len(value.shape) == 2 else value
            parts.append(value)
            if f.neighbors:
                shared += [value[..., c] for c in range(f.size(task))]
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
        gathered = xp.gather_agents(columns + flag_columns + shared, index)
        flags = gathered[2 * d : 2 * d + len(flag_columns)]
        shared_slots = gathered[2 * d + len(flag_columns) :]
        gathered = gathered[: 2 * d]
        slot_features = [
            (g - col[..., None]) * scale
            for g, col, scale in zip(gathered, columns, scales, strict=True)
        ]
        if status is None:
            slot_features.append(xp.ones((B, N, k_real), like=x))
        else:
            # A slot holds a neighbour where both are present and it is another agent
            # (the ranking puts the others not present, and the agent itself, last).
            real, active, slot_ids = flags
            real = real * present[..., None] * xp.astype(slot_ids != ids[..., None], x)
            slot_features = [f * real for f in slot_features] + [real]
        if getattr(task, "observe_status", False):
            slot_features.append(
                xp.ones((B, N, k_real), like=x) if status is None else active * real
            )
        slot_features += shared_slots if status is None else [g * real for g in shared_slots]
        parts.append(xp.stack(slot_features, axis=-1).reshape(B, N, k_real * block))
    if k > k_real:
        parts.append(xp.zeros((B, N, (k - k_real) * block), like=x))
    obs = xp.concat(parts, axis=-1)
    return xp.float32(xp.clip(obs, -OBS_BOUND, OBS_BOUND))
