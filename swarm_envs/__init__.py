"""swarm_envs: Gymnasium and PettingZoo environments for learned swarm control."""

__version__ = "0.1.0"
