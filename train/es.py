"""Evolution strategies: a deterministic shared policy trained on its own return.

``algo: ES`` trains the mean of the shared policy's network (the actor of SB3's PPO
``MlpPolicy``, ``tanh`` hidden layers, actions clipped to [−1, 1]) by OpenAI's
evolution strategies: each generation draws ``population / 2`` Gaussian directions
``ε_k``, runs the candidates ``θ ± σ ε_k`` (and ``θ`` itself, for the log) on the same
``n_swarms`` seeded episodes each (common random numbers: every candidate meets the
same starts, informed agents and failure schedules; the observation and action noise of
perturbed configs and the piecewise model's random force are drawn step by step for all
swarms at once, so they differ between candidates), shapes the candidates' mean returns
into centred ranks and steps ``θ`` along ``Σ_k (rank⁺_k − rank⁻_k) ε_k / (population σ)``
with Adam, less ``weight_decay · θ``. All candidates' episodes step together on one
batched core (``(population + 1) × n_swarms`` swarms), each until its episode ends; a
candidate that makes its swarm unstable ends that episode there (the config's
``on_unstable`` is taken as ``"truncate"``), which its return pays for.

Where PPO improves a Gaussian policy's expected return, with its exploration noise in
every action, ES improves the return of the policy that is evaluated, the noise-free
mean: a residual policy (``residual: <baseline>``) starts at its baseline's return
(the action layer starts near zero) and moves only where the deterministic return
rises. ``total_timesteps`` counts the agent-steps every candidate's episodes took.
With ``residual_corrects: gains``, ``θ`` is a gain schedule's weights instead
(:mod:`train.gain_schedule`: the baseline acts with gains that depend on each agent's
observation; zeros at the start, the baseline itself), recorded in the model's residual
record; the PPO model's actor then stays untrained.

A run writes what an SB3 run writes (:mod:`train.train`): ``model.zip`` is a PPO model
whose actor holds ``θ`` (its value function is untrained; its log standard deviation
is ``residual_log_std`` with a ``residual``, else SB3's 0), so every evaluation tool
loads it as any shared policy;
checkpoints (``checkpoints/step_<timesteps>/``: ``model.zip``, ``es_state.npz`` with
``θ`` and Adam's moments, ``state.json`` with the generation, the generator's state,
the training seconds and the last generations' centre returns) are taken between
generations every ``checkpoint_seconds`` and ``checkpoint_freq`` timesteps, on a stop
request and at the end; ``resume`` continues from the newest, and gives the same ``θ``
as an uninterrupted run.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any, Protocol

import numpy as np

#: The name of the algorithm in ``TrainConfig.algo``.
ES = "ES"

#: ES's hyperparameters (``hyperparams`` of an ``algo: ES`` config) and their defaults.
ES_DEFAULTS: dict[str, float | int] = {
    "population": 32,
    "noise_std": 0.05,
    "learning_rate": 0.02,
    "weight_decay": 0.005,
}

#: Adam's moment decays and its denominator's guard.
_ADAM = (0.9, 0.999, 1e-8)

#: The first word of every generation's episode seed (``(_STREAM, seed, generation)``).
_STREAM = 0x45_53

#: Generations whose centre's return ``meta.json`` (and a checkpoint) keeps.
_HISTORY = 20

#: A checkpoint's ES state, beside its ``model.zip`` and ``state.json``.
STATE_FILE = "es_state.npz"


def check_es_hyperparams(hyperparams: Mapping[str, Any]) -> dict[str, float | int]:
    """ES's hyperparameters: :data:`ES_DEFAULTS` updated by ``hyperparams``, checked.

    Raises:
        ValueError: a key that is not one of :data:`ES_DEFAULTS`, an odd or too small
            ``population`` (antithetic pairs: an even number ``≥ 2``), a ``noise_std``
            or ``learning_rate`` not ``> 0``, or a ``weight_decay`` below 0.
    """
    out = dict(ES_DEFAULTS)
    for key, value in hyperparams.items():
        if key not in ES_DEFAULTS:
            allowed = ", ".join(sorted(ES_DEFAULTS))
            raise ValueError(
                f"hyperparams.{key} is not an ES argument; allowed: {allowed} (a PPO or SAC "
                "recipe's hyperparams do not carry over to algo=ES: start from an ES recipe "
                "such as configs/train/residual_es.yaml)"
            )
        if isinstance(value, str):
            try:
                value = float(value)
            except ValueError:
                raise ValueError(f"hyperparams.{key} must be a number, got {value!r}") from None
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not math.isfinite(value)
        ):
            raise ValueError(f"hyperparams.{key} must be a finite number, got {value!r}")
        out[key] = value
    population = out["population"]
    if int(population) != population or population < 2 or int(population) % 2:
        raise ValueError(
            "hyperparams.population must be an even integer >= 2 (antithetic pairs), "
            f"got {population!r}"
        )
    out["population"] = int(population)
    for key in ("noise_std", "learning_rate"):
        if out[key] <= 0:
            raise ValueError(f"hyperparams.{key} must be > 0, got {out[key]!r}")
    if out["weight_decay"] < 0:
        raise ValueError(f"hyperparams.weight_decay must be >= 0, got {out['weight_decay']!r}")
    return out


class Actor(Protocol):
    """What ES trains: a flat parameter vector ``θ`` of ``size`` entries, and the
    deterministic actions of many such vectors at once (:class:`ActorParameters`, an
    SB3 actor; :class:`train.gain_schedule.ScheduleActor`, a gain schedule)."""

    size: int
    #: Whether each row's action is computed alone, bit for bit the same whatever rows
    #: come with it: then a generation's swarms whose episodes ended are no longer
    #: observed or acted for (an SB3 actor's batched matrix products are not).
    rowwise: bool

    def flat(self) -> np.ndarray: ...

    def load(self, theta: np.ndarray) -> None: ...

    def actions(self, thetas: np.ndarray, obs: np.ndarray) -> np.ndarray: ...


class ActorParameters:
    """The actor of an SB3 ``ActorCriticPolicy`` as one flat vector, and its forward
    pass for many parameter vectors at once.

    The actor is the policy's ``mlp_extractor.policy_net`` (linear layers, each followed
    by ``tanh``) and its ``action_net`` (linear); the deterministic action is that
    output clipped to [−1, 1], as SB3's ``predict`` gives it for a box of [−1, 1].
    """

    def __init__(self, policy: Any) -> None:
        import torch

        hidden = [m for m in policy.mlp_extractor.policy_net if isinstance(m, torch.nn.Linear)]
        for module in policy.mlp_extractor.policy_net:
            if not isinstance(module, torch.nn.Linear | torch.nn.Tanh):
                raise ValueError(
                    f"ES trains actors of linear layers and tanh; the policy has {module!r}"
                )
        self.rowwise = False  # batched matrix products: a row's sums depend on the batch
        self.layers = [*hidden, policy.action_net]
        self.shapes = [(m.in_features, m.out_features) for m in self.layers]
        self.size = sum(i * o + o for i, o in self.shapes)

    def flat(self) -> np.ndarray:
        """The actor's parameters as one float64 vector (weights transposed: in × out)."""
        parts = []
        for m in self.layers:
            parts.append(m.weight.detach().cpu().numpy().T.ravel())
            parts.append(m.bias.detach().cpu().numpy().ravel())
        return np.concatenate(parts).astype(np.float64)

    def load(self, theta: np.ndarray) -> None:
        """Write ``theta`` (:meth:`flat`'s layout) into the actor's layers."""
        import torch

        with torch.no_grad():
            for m, (w, b) in zip(self.layers, self._split(theta[None]), strict=True):
                m.weight.copy_(torch.as_tensor(w[0].T, dtype=m.weight.dtype))
                m.bias.copy_(torch.as_tensor(b[0], dtype=m.bias.dtype))

    def _split(self, thetas: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        out, at = [], 0
        for i, o in self.shapes:
            w = thetas[:, at : at + i * o].reshape(-1, i, o)
            at += i * o
            out.append((w, thetas[:, at : at + o]))
            at += o
        return out

    def actions(self, thetas: np.ndarray, obs: np.ndarray) -> np.ndarray:
        """Deterministic actions ``(P, n, d)`` of the ``P`` parameter vectors ``thetas``
        ``(P, size)`` for their observations ``obs`` ``(P, n, obs_dim)``, in float32."""
        h = obs.astype(np.float32, copy=False)
        layers = self._split(thetas.astype(np.float32))
        for k, (w, b) in enumerate(layers):
            h = np.matmul(h, w) + b[:, None, :]
            if k < len(layers) - 1:
                np.tanh(h, out=h)
        return np.clip(h, -1.0, 1.0)


class Rollouts:
    """Episodes of many parameter vectors on one batched core, with common starts.

    ``population`` candidates × ``episodes`` swarms: block ``k`` (swarms ``k·episodes``
    to ``(k+1)·episodes − 1``) is candidate ``k``'s. Every block is reset from a
    generator seeded alike, so swarm ``j`` of every block starts the same.
    """

    def __init__(
        self,
        cfg: Any,
        actor: Actor,
        baseline: Any,
        candidates: int,
        episodes: int,
        scale: float = 1.0,
    ) -> None:
        from swarm_envs.envs.backends import make_core

        self.cfg = replace(cfg, on_unstable="truncate")
        self.actor = actor
        self.baseline = baseline
        self.scale = scale
        self.candidates = candidates
        self.episodes = episodes
        self.core = make_core(self.cfg, batch=candidates * episodes)

    def returns(self, thetas: np.ndarray, entropy: tuple[int, ...]) -> tuple[np.ndarray, int]:
        """Each candidate's mean return over its episodes ``(P,)``, and the agent-steps
        taken (every candidate's swarms until their episodes ended). Every block's starts
        come from ``numpy.random.default_rng(SeedSequence(entropy))``: a tuple, so that
        no generation meets the episodes of an integer seed (an evaluation's)."""
        from swarm_envs.envs.backends import make_core
        from swarm_envs.envs.cores.numpy import keeps_rows, shrink_due

        core, P, M = self.core, self.candidates, self.episodes
        if thetas.shape[0] != P:
            raise ValueError(f"expected {P} parameter vectors, got {thetas.shape[0]}")
        B, N = P * M, self.cfg.n_agents
        for k in range(P):
            block = np.zeros(B, bool)
            block[k * M : (k + 1) * M] = True
            core.reset(np.random.default_rng(np.random.SeedSequence(entropy)), which=block)
        total = np.zeros(B)
        done = np.zeros(B, bool)
        agent_steps = 0
        # A row-wise actor's rollouts shrink the core to the live swarms (shrink_due; a
        # stalled episode would keep every swarm stepping to max_steps): the same
        # returns, bit for bit (SwarmNavCore.keep).
        keeper = core if self.actor.rowwise and keeps_rows(core) else None
        rows = np.arange(B)  # the swarm of each row of the core
        for _ in range(self.cfg.max_steps):
            live = ~done[rows]
            if keeper is not None and shrink_due(int(live.sum()), len(rows)):
                keeper.keep(np.flatnonzero(live))
                rows, live = rows[live], live[live]
            # With a row-wise actor, the swarms whose episodes ended step on with zero
            # actions, unobserved; their steps are not counted either way.
            which = live if self.actor.rowwise and not live.all() else None
            obs = np.asarray(core.observe(which))
            action = self._actions(thetas, obs, rows, which)
            reward, terminated, truncated, _ = core.step(action)
            total[rows[live]] += reward[live]
            agent_steps += int(live.sum()) * N
            done[rows] |= terminated | truncated
            if done.all():
                break
        if len(rows) < B:  # the next generation starts on a whole batch again
            self.core = make_core(self.cfg, batch=B)
        return total.reshape(P, M).mean(axis=1), agent_steps

    def _actions(
        self, thetas: np.ndarray, obs: np.ndarray, rows: np.ndarray, which: np.ndarray | None
    ) -> np.ndarray:
        """The actions ``(R, N, d)`` for the core's ``R`` rows, whose swarms are ``rows``,
        given the observations ``obs`` of the rows ``which`` (bool ``(R,)``; ``None``:
        all, the whole batch): each from its candidate's parameters (and the baseline),
        zero for the other rows: an episode that has ended costs no observation and no
        forward pass while the others finish."""
        from train.residual import apply_correction

        P, M, N = self.candidates, self.episodes, self.cfg.n_agents
        od = obs.shape[-1]
        if which is None and len(rows) == P * M:  # block k of the swarms is candidate k's
            out = self.actor.actions(thetas, obs.reshape(P, M * N, od))
        else:  # a row-wise actor: each observed swarm with its own candidate's vector
            seen = rows if which is None else rows[which]
            out = self.actor.actions(thetas[seen // M], obs)
        out = out.reshape(len(obs), N, -1)  # (observed swarms, N, d)
        if self.baseline is not None:
            base, _ = self.baseline.predict(obs.reshape(-1, od))
            out = apply_correction(base, out.reshape(base.shape), self.scale).reshape(out.shape)
        if which is None:
            return out
        action = np.zeros((len(rows), N, out.shape[-1]), np.float32)
        action[which] = out
        return action


def centred_ranks(values: np.ndarray) -> np.ndarray:
    """``values``' ranks scaled into [−0.5, 0.5] (ties in order of appearance).

    >>> centred_ranks(np.array([3.0, -1.0, 10.0])).tolist()
    [0.0, -0.5, 0.5]
    """
    ranks = np.empty(values.size)
    ranks[np.argsort(values, kind="stable")] = np.arange(values.size)
    return ranks / max(values.size - 1, 1) - 0.5


class EvolutionStrategy:
    """OpenAI-ES's state and update (module docstring): ``θ``, Adam's moments, the
    generation count and the generator of the directions."""

    def __init__(self, theta: np.ndarray, hyper: Mapping[str, float | int], seed: int) -> None:
        self.theta = np.asarray(theta, np.float64).copy()
        self.hyper = dict(hyper)
        self.m = np.zeros_like(self.theta)
        self.v = np.zeros_like(self.theta)
        self.generation = 0
        self.rng = np.random.default_rng(seed)

    def candidates(self) -> tuple[np.ndarray, np.ndarray]:
        """The directions ``ε`` ``(P/2, size)`` and the candidates ``θ + σε, θ − σε, θ``
        ``(P + 1, size)``."""
        half = int(self.hyper["population"]) // 2
        eps = self.rng.standard_normal((half, self.theta.size))
        sigma = float(self.hyper["noise_std"])
        plus, minus = self.theta + sigma * eps, self.theta - sigma * eps
        return eps, np.concatenate([plus, minus, self.theta[None]])

    def update(self, eps: np.ndarray, returns: np.ndarray) -> None:
        """One Adam step along the rank-shaped estimate of the return's gradient;
        ``returns`` are the ``P`` perturbed candidates' (plus, then minus)."""
        half = eps.shape[0]
        ranks = centred_ranks(returns)
        sigma = float(self.hyper["noise_std"])
        grad = (ranks[:half] - ranks[half:]) @ eps / (2 * half * sigma)
        grad -= float(self.hyper["weight_decay"]) * self.theta
        b1, b2, tiny = _ADAM
        self.generation += 1
        self.m = b1 * self.m + (1 - b1) * grad
        self.v = b2 * self.v + (1 - b2) * grad * grad
        m_hat = self.m / (1 - b1**self.generation)
        v_hat = self.v / (1 - b2**self.generation)
        self.theta = self.theta + float(self.hyper["learning_rate"]) * m_hat / (
            np.sqrt(v_hat) + tiny
        )

    def save(self, path: Path) -> dict[str, Any]:
        """Write ``θ`` and the moments to ``path`` (npz); return the rest (JSON-safe)."""
        np.savez(path, theta=self.theta, m=self.m, v=self.v)
        return {"generation": self.generation, "rng": self.rng.bit_generator.state}

    def restore(self, path: Path, state: Mapping[str, Any]) -> None:
        """The state :meth:`save` wrote."""
        with np.load(path) as data:
            self.theta, self.m, self.v = data["theta"], data["m"], data["v"]
        self.generation = int(state["generation"])
        self.rng.bit_generator.state = state["rng"]


def policy_model(tc: Any) -> Any:
    """The PPO model whose actor ES trains (seeded: its initial actor is ``θ₀``), on a
    one-swarm training env (only its spaces are used)."""
    from train.train import build_model, make_training_env

    small = replace(
        tc,
        n_swarms=1,
        algo="PPO",
        hyperparams={"n_steps": 2, "batch_size": 2},
        residual_corrects="action",  # the model only carries a gain schedule's record
    )
    venv = make_training_env(small)
    model = build_model(small, venv)
    return model


def train_es(
    tc: Any,
    out: Path,
    *,
    progress_bar: bool,
    verbose: int,
    resume: bool,
    stop: Any,
    handle_signals: bool,
) -> Path:
    """Train ``tc`` (``algo: ES``) into ``out``, which :func:`train.train.train` has
    checked (and, without ``resume``, emptied). Returns ``out/model.zip``."""
    import contextlib

    from stable_baselines3 import PPO

    from train.callbacks import progress_line
    from train.checkpoints import (
        checkpoint_timesteps,
        copy_atomic,
        latest_checkpoint,
        write_atomic,
        write_checkpoint,
    )
    from train.gain_schedule import ScheduleActor
    from train.interrupt import TrainingInterrupted, stop_on_signals
    from train.residual import RESIDUAL, make_baseline
    from train.train import PROGRESS_LINE_SECONDS, run_meta

    cfg = tc.swarm_config()
    ckpt = latest_checkpoint(out) if resume else None
    # A resumed run keeps the baseline gains its model recorded, as SB3's runs do.
    model = policy_model(tc) if ckpt is None else PPO.load(ckpt / "model.zip", device=tc.device)
    record = getattr(model, RESIDUAL, None) or {}
    baseline = make_baseline(tc.residual, cfg, record["gains"]) if tc.residual else None
    actor: Actor
    if tc.residual_corrects == "gains":
        assert tc.residual is not None  # TrainConfig checked
        # The schedule acts as the baseline with scheduled gains: no action to add.
        actor, baseline = ScheduleActor(model, baseline, tc.residual), None
    else:
        actor = ActorParameters(model.policy)
    hyper = check_es_hyperparams(tc.hyperparams)
    es = EvolutionStrategy(actor.flat(), hyper, tc.seed)
    timesteps, seconds_before = 0, 0.0
    history: list[dict[str, float]] = []
    if resume:
        assert ckpt is not None  # train.train checked
        state = json.loads((ckpt / "state.json").read_text())
        es.restore(ckpt / STATE_FILE, state["es"])
        timesteps, seconds_before = int(state["timesteps"]), float(state["train_seconds"])
        history.extend(state.get("history", []))
    P = int(hyper["population"])
    rollouts = Rollouts(cfg, actor, baseline, P + 1, tc.n_swarms, record.get("scale", 1.0))
    clock = time.perf_counter()
    saved_at = (time.monotonic(), timesteps)

    def seconds() -> float:
        return seconds_before + time.perf_counter() - clock

    def publish(status: str, ckpt: Path) -> None:
        copy_atomic(ckpt / "model.zip", out / "model.zip")
        meta = run_meta(
            tc, status, checkpoint_timesteps(ckpt), str(ckpt.relative_to(out)), seconds()
        )
        meta["es"] = {"generations": es.generation, "centre_returns": history[-_HISTORY:]}
        write_atomic(out / "meta.json", json.dumps(meta, indent=2) + "\n")

    def fill(tmp: Path) -> None:
        actor.load(es.theta)
        model.num_timesteps = timesteps
        model.save(tmp / "model.zip")
        extra = es.save(tmp / STATE_FILE)
        state = {
            "timesteps": timesteps,
            "train_seconds": round(seconds(), 3),
            "es": extra,
            "history": history[-_HISTORY:],
        }
        (tmp / "state.json").write_text(json.dumps(state, indent=2) + "\n")

    def checkpoint() -> Path:
        final = write_checkpoint(out, timesteps, fill, tc.checkpoint_keep)
        publish("running", final)
        return final

    if verbose:
        what = f"resuming at {timesteps:,} timesteps" if resume else "training"
        print(
            f"{what} ES ({P} candidates × {tc.n_swarms} episodes, {actor.size} parameters) for "
            f"{tc.total_timesteps:,} timesteps; N = {cfg.n_agents}; out = {out}"
        )
    last_line, start_steps = time.monotonic(), timesteps

    def seconds_now() -> float:
        return time.perf_counter() - clock

    guards = stop_on_signals(stop) if handle_signals else contextlib.nullcontext(stop)
    with guards:
        ckpt = checkpoint() if not resume else latest_checkpoint(out)
        assert ckpt is not None
        while timesteps < tc.total_timesteps:
            if stop.requested:
                ckpt = checkpoint()
                publish("interrupted", ckpt)
                assert stop.signum is not None
                raise TrainingInterrupted(stop.signum, timesteps, out, ckpt)
            eps, thetas = es.candidates()
            returns, used = rollouts.returns(thetas, (_STREAM, tc.seed, es.generation))
            es.update(eps, returns[:P])
            timesteps += used
            history.append(
                {"generation": es.generation, "timesteps": timesteps, "return": float(returns[P])}
            )
            clock_now, steps_then = saved_at
            by_time = (
                tc.checkpoint_seconds > 0 and time.monotonic() - clock_now >= tc.checkpoint_seconds
            )
            by_steps = tc.checkpoint_freq > 0 and timesteps - steps_then >= tc.checkpoint_freq
            if by_time or by_steps:
                ckpt = checkpoint()
                saved_at = (time.monotonic(), timesteps)
            if progress_bar and time.monotonic() - last_line >= PROGRESS_LINE_SECONDS:
                last_line = time.monotonic()
                line = progress_line(timesteps, tc.total_timesteps, start_steps, seconds_now())
                print(
                    f"{line}; generation {es.generation}, centre's return {returns[P]:.3f}",
                    flush=True,
                )
        ckpt = checkpoint()
        publish("completed", ckpt)
    if verbose:
        print(f"saved {out / 'model.zip'} after {seconds():.0f} s ({es.generation} generations)")
    return out / "model.zip"
