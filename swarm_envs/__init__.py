"""swarm_envs: Gymnasium and PettingZoo environments for learned swarm control.

``import swarm_envs`` registers ``swarm_envs/SwarmNav-v0`` with Gymnasium.
"""

from gymnasium.envs.registration import register, registry

__version__ = "0.1.0"

ENV_ID = "swarm_envs/SwarmNav-v0"

if ENV_ID not in registry:
    register(
        id=ENV_ID,
        entry_point="swarm_envs.envs.swarm_nav:SwarmNavEnv",
        max_episode_steps=400,
    )

from swarm_envs import swarm_nav_v0  # noqa: E402

__all__ = ["ENV_ID", "__version__", "swarm_nav_v0"]
