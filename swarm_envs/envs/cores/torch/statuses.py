"""The torch core's agent statuses: each agent's status on the host and on the device.

:class:`DeviceStatuses` is held by :class:`~swarm_envs.envs.cores.torch.core.TorchSwarmNavCore`.
A core whose config needs statuses (``perturbations.needs_masks`` or ``observe_status``)
passes them to its fused step and its substep function
(:mod:`swarm_envs.envs.cores.torch.step`), which apply the masks of
:mod:`~swarm_envs.envs.task.agent_status`; a core whose config needs none runs the
functions without them and refuses statuses. What a change of statuses does to the
episode is the task layer's (:mod:`swarm_envs.envs.task.layer`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import torch

if TYPE_CHECKING:
    from swarm_envs.config import SwarmConfig

__all__ = ["DeviceStatuses"]


class DeviceStatuses:
    """Each agent's status ``(B, N)`` int8 for a torch core's functions.

    Attributes:
        enabled: whether the functions take statuses (``cfg.needs_statuses``).
        host: the statuses as last given, on the host (``None`` before).
        tensor: the same on the device (every agent active before).
    """

    def __init__(self, cfg: SwarmConfig, batch: int, device: torch.device) -> None:
        self.enabled = bool(cfg.needs_statuses)
        self.host: np.ndarray | None = None
        self.tensor = torch.zeros((batch, cfg.n_agents), dtype=torch.int8, device=device)

    def args(self, rows: torch.Tensor | None = None) -> tuple[torch.Tensor, ...]:
        """The functions' last argument, the statuses (of swarms ``rows``), or nothing
        where the config needs none."""
        if not self.enabled:
            return ()
        return (self.tensor if rows is None else self.tensor[rows],)

    def take(self, status: np.ndarray) -> None:
        """New statuses ``(B, N)`` int8 (checked).

        Raises:
            ValueError: the config needs no statuses (the functions were built without
                them).
        """
        if not self.enabled:
            raise ValueError(
                "set_status needs a config with agent statuses (perturbations that remove, "
                "freeze or add agents, or observe_status); this core's config has none"
            )
        self.host = status
        self.tensor = torch.as_tensor(status, device=self.tensor.device).clone()
