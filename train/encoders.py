"""A permutation-invariant encoder of an agent's neighbours for SB3's policies.

An agent's observation (``swarm_envs.envs.task.observation``) is its own features
followed by ``k`` neighbour slots, nearest first, each ending its position and velocity
with a mask (1: a real neighbour, 0: padding). The default policy reads all of it as one
flat vector, so the same neighbour seen in another slot is another input.
:class:`NeighborSetEncoder` (``encoder: deepsets`` in a train config) reads the slots as
a set instead (DeepSets): one small network ``φ`` encodes every slot alike, the codes of
the real neighbours are pooled by their mean and their maximum, and the pooled codes go
to the policy and value networks beside the agent's own features. Reordering the
neighbours does not change the features, and a padding slot contributes nothing.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import torch
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

from swarm_envs.config import SwarmConfig

__all__ = ["ENCODERS", "NeighborSetEncoder", "encoder_kwargs"]

#: The values of ``TrainConfig.encoder`` beside ``None`` (the flat observation).
ENCODERS = ("deepsets",)


class NeighborSetEncoder(BaseFeaturesExtractor):
    """DeepSets features of one agent's observation: ``[own, mean_j φ(s_j), max_j φ(s_j)]``
    over its real neighbour slots ``s_j`` (zeros where it has none).

    Args:
        observation_space: the per-agent observation box, ``(own + k · block,)``.
        own: entries of the agent's own features (``observation.own_size``).
        k: neighbour slots.
        block: entries per slot (``observation.block_size``).
        mask: the index, within a slot, of its mask entry.
        width: the size of ``φ``'s two layers and of each pooled code.

    >>> import numpy as np
    >>> space = gym.spaces.Box(-1.0, 1.0, (4 + 2 * 5,), np.float32)
    >>> enc = NeighborSetEncoder(space, own=4, k=2, block=5, mask=4, width=3)
    >>> obs = torch.zeros(1, 14)
    >>> obs[0, 4:9] = torch.tensor([0.5, 0.0, 0.1, 0.0, 1.0])   # one real neighbour
    >>> swapped = torch.cat([obs[:, :4], obs[:, 9:], obs[:, 4:9]], dim=1)
    >>> bool(torch.equal(enc(obs), enc(swapped))), enc.features_dim
    (True, 10)
    """

    def __init__(
        self,
        observation_space: gym.spaces.Box,
        own: int,
        k: int,
        block: int,
        mask: int,
        width: int = 32,
    ) -> None:
        size = int(observation_space.shape[0])
        if size != own + k * block or not 0 <= mask < block or min(own, k, width) < 1:
            raise ValueError(
                f"NeighborSetEncoder: an observation of {size} entries is not {own} own "
                f"entries and {k} slots of {block} with the mask at {mask} (width {width})"
            )
        super().__init__(observation_space, features_dim=own + 2 * width)
        self.own, self.k, self.block, self.mask = own, k, block, mask
        self.phi = nn.Sequential(
            nn.Linear(block, width), nn.Tanh(), nn.Linear(width, width), nn.Tanh()
        )

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        own = observations[:, : self.own]
        slots = observations[:, self.own :].reshape(-1, self.k, self.block)
        real = slots[..., self.mask : self.mask + 1] > 0.5  # (B, k, 1)
        codes = self.phi(slots)
        weight = real.to(codes.dtype)
        count = weight.sum(dim=1).clamp(min=1.0)
        mean = (codes * weight).sum(dim=1) / count
        # φ ends in tanh, so -2 is below every code: the max over the real slots, and 0
        # for an agent with none.
        peak = torch.where(real, codes, torch.full_like(codes, -2.0)).amax(dim=1)
        peak = torch.where(real.any(dim=1), peak, torch.zeros_like(peak))
        return torch.cat([own, mean, peak], dim=1)


def encoder_kwargs(cfg: SwarmConfig, width: int) -> dict[str, Any]:
    """``features_extractor_kwargs`` of :class:`NeighborSetEncoder` for ``cfg``'s
    per-agent observation."""
    from swarm_envs.envs.task.observation import block_size, own_size

    return {
        "own": own_size(cfg),
        "k": cfg.n_neighbors,
        "block": block_size(cfg),
        "mask": 2 * cfg.dim,
        "width": int(width),
    }
