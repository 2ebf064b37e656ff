"""Residual policies: a learned correction on top of a simple baseline's action.

A residual policy acts ``a_i = clip(b(o_i) + c · r_θ(o_i), −1, 1)``: the baseline ``b``
(a controller of :mod:`agents`, e.g. the tuned saturated PD law) plus a learned
correction ``r_θ``, scaled by ``c = TrainConfig.residual_scale`` (1 by default; a
smaller ``c`` keeps the policy within ``c`` of the baseline's action on every axis, a
trust region that training cannot leave). SB3's PPO starts its Gaussian policy's mean
near zero (the action layer is initialised small), so training starts at the
baseline's return and only has to learn what the baseline misses.
``TrainConfig.residual`` names the baseline; training steps the env through
:class:`ResidualVecEnv`, and the model records the baseline, its gains and the scale
(:data:`RESIDUAL`, saved in the model zip), so that :func:`as_policy` rebuilds the
same policy at evaluation, whatever the tuned table says by then.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs

from swarm_envs.config import SwarmConfig

__all__ = [
    "RESIDUAL",
    "CriticWarmup",
    "ResidualPolicy",
    "ResidualVecEnv",
    "apply_correction",
    "as_policy",
    "check_baseline_name",
    "check_residual_scale",
    "make_baseline",
    "residual_record",
]

#: The attribute of an SB3 model that names the baseline it corrects (saved in the zip).
RESIDUAL = "swarm_residual"

#: Attributes of a controller recorded with a residual model (its gains).
_GAIN_ATTRS = (
    "k_p",
    "k_d",
    "k_v",
    "k_c",
    "k_l",
    "tether",
    "lead",
    "flock_lead",
    "goal_pull",
    "saturation",
    "approach",
    "spin",
    "omega",
)

#: Gains a controller gained after residual models recorded it, with the value that
#: leaves it as it was: a record without them rebuilds the baseline it was trained on,
#: not today's tuned one (``follow``'s leader tether, its followers' leads and its
#: leader's saturated goal pull, off before they existed).
_GAINS_BEFORE_RECORDED = {
    "follow": {"k_l": 0.0, "lead": 0.0, "goal_pull": "raw", "flock_lead": 0.0}
}


def check_baseline_name(name: Any) -> str:
    """``name`` if it names a controller a policy can correct (any of
    :data:`agents.CONTROLLERS` but the random one), else ``ValueError`` listing them."""
    from agents import CONTROLLERS

    known = [n for n in CONTROLLERS if n != "random"]
    if name not in known:
        raise ValueError(f"residual must be null or one of {', '.join(known)}, got {name!r}")
    return name


def make_baseline(name: str, cfg: SwarmConfig, gains: Mapping[str, Any] | None = None) -> Any:
    """The controller ``name`` of :data:`agents.CONTROLLERS` for ``cfg``, with ``gains``
    (``None``: its tuned or default gains; recorded gains that lack a gain added to the
    controller since are completed with the value that leaves it as it was)."""
    from agents import CONTROLLERS, make_controller

    check_baseline_name(name)
    if gains is None:
        return make_controller(name, cfg)
    return CONTROLLERS[name](cfg, **{**_GAINS_BEFORE_RECORDED.get(name, {}), **dict(gains)})


def check_residual_scale(scale: Any) -> float:
    """``scale`` as a float if it is a number in (0, 1], else ``ValueError``."""
    if isinstance(scale, bool) or not isinstance(scale, int | float) or not 0 < scale <= 1:
        raise ValueError(f"residual_scale must be a number in (0, 1], got {scale!r}")
    return float(scale)


def residual_record(name: str, baseline: Any, scale: float = 1.0) -> dict[str, Any]:
    """What a residual model records: the baseline's name and gains, and the scale of
    the correction (:class:`ResidualVecEnv`)."""
    gains = {k: getattr(baseline, k) for k in _GAIN_ATTRS if hasattr(baseline, k)}
    return {"baseline": name, "gains": gains, "scale": check_residual_scale(scale)}


def apply_correction(base: Any, correction: Any, scale: float) -> np.ndarray:
    """The action of a residual policy: ``clip(base + scale · clip(correction, −1, 1),
    −1, 1)`` in float32 (one definition for training, evaluation and ES)."""
    total = np.asarray(base, np.float32) + scale * np.clip(correction, -1.0, 1.0)
    return np.clip(total, -1.0, 1.0).astype(np.float32, copy=False)


class ResidualVecEnv(VecEnvWrapper):
    """A VecEnv whose actions are corrections: it steps the wrapped env with
    ``clip(baseline(obs) + scale · action, −1, 1)`` (:func:`apply_correction`), ``obs``
    the observations the actions answer."""

    def __init__(self, venv: VecEnv, baseline: Any, scale: float = 1.0) -> None:
        super().__init__(venv)
        self.baseline = baseline
        self.scale = check_residual_scale(scale)
        self._obs: VecEnvObs | None = None

    def reset(self) -> VecEnvObs:
        self._obs = self.venv.reset()
        return self._obs

    def step_async(self, actions: np.ndarray) -> None:
        if self._obs is None:
            raise RuntimeError("ResidualVecEnv: step before reset")
        base, _ = self.baseline.predict(self._obs)
        self.venv.step_async(apply_correction(base, actions, self.scale))

    def step_wait(self) -> Any:
        obs, rewards, dones, infos = self.venv.step_wait()
        self._obs = obs
        return obs, rewards, dones, infos


class ResidualPolicy:
    """A residual model as one policy (SB3's ``predict``): baseline plus the correction
    times ``scale`` (:func:`apply_correction`)."""

    def __init__(self, model: Any, baseline: Any, scale: float = 1.0) -> None:
        self.model = model
        self.baseline = baseline
        self.scale = check_residual_scale(scale)
        self.observation_space = model.observation_space
        self.action_space = model.action_space
        from train.evaluate.policies import TRAINED_ENV

        setattr(self, TRAINED_ENV, getattr(model, TRAINED_ENV, None))
        setattr(self, RESIDUAL, getattr(model, RESIDUAL, None))

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        correction, state = self.model.predict(
            observation, state=state, episode_start=episode_start, deterministic=deterministic
        )
        base, _ = self.baseline.predict(observation)
        return apply_correction(base, correction, self.scale), state


class CriticWarmup(BaseCallback):
    """Hold the policy (actor) still for the first ``timesteps``: only the value function
    learns, from rollouts of the baseline plus the initial, near-zero correction.

    An actor updated against an untrained critic drifts away from the baseline before
    the advantages mean anything; with the critic warmed up first, the first policy
    updates already point somewhere better (the burn-in of residual policy learning).
    The actor's parameters stop receiving gradients (``requires_grad`` off) until then.
    """

    def __init__(self, timesteps: int, verbose: int = 0) -> None:
        super().__init__(verbose)
        self.timesteps = int(timesteps)
        self._frozen: list[Any] = []

    def _actor_parameters(self) -> list[Any]:
        policy = self.model.policy
        if not isinstance(policy, ActorCriticPolicy):
            raise TypeError(
                f"CriticWarmup holds the actor of an actor-critic policy (PPO) still, "
                f"got {type(policy).__name__}"
            )
        parts = [policy.action_net, policy.mlp_extractor.policy_net]
        params = [p for part in parts for p in part.parameters()]
        log_std = getattr(policy, "log_std", None)
        return [*params, log_std] if log_std is not None else params

    def _on_training_start(self) -> None:
        if self.model.num_timesteps < self.timesteps:
            self._frozen = [p for p in self._actor_parameters() if p.requires_grad]
            for p in self._frozen:
                p.requires_grad_(False)

    def _on_rollout_end(self) -> None:
        if self._frozen and self.model.num_timesteps >= self.timesteps:
            self._release()

    def _on_training_end(self) -> None:
        self._release()

    def _release(self) -> None:
        for p in self._frozen:
            p.requires_grad_(True)
        self._frozen = []

    def _on_step(self) -> bool:
        return True


def as_policy(model: Any) -> Any:
    """``model`` as the policy it acts as: a :class:`ResidualPolicy` for a model that
    records a baseline (:data:`RESIDUAL`; a record without a scale is a correction at
    scale 1), a :class:`~train.gain_schedule.GainScheduledPolicy` for one that records
    a gain schedule, the model itself otherwise. A :class:`ResidualPolicy` is returned
    as it is: it already acts as its baseline plus its correction (wrapping it again
    would add the baseline twice)."""
    if isinstance(model, ResidualPolicy):
        return model
    record = getattr(model, RESIDUAL, None)
    if not isinstance(record, Mapping):
        return model
    from swarm_envs.config import load_swarm_config
    from train.evaluate.policies import TRAINED_ENV

    trained = getattr(model, TRAINED_ENV, None) or {}
    cfg = load_swarm_config(None, dict(trained.get("env_config") or {}))
    baseline = make_baseline(record["baseline"], cfg, record.get("gains"))
    if "schedule" in record:  # a gain schedule (residual_corrects: gains)
        from train.gain_schedule import GainScheduledPolicy

        return GainScheduledPolicy(model, baseline, record["baseline"], record["schedule"])
    return ResidualPolicy(model, baseline, record.get("scale", 1.0))
