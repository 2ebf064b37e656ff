"""Train and evaluate the entries of a benchmark matrix.

For each entry (:class:`~train.benchmark.matrix.Entry`) and training seed ``k`` the
learned policy is trained into ``OUT/models/<entry>/seed<k>/`` with
:func:`train.train.train`, one run after another in this process (or several at once,
each in a process of its own: :mod:`train.benchmark.parallel`). A folder whose run
is ``completed`` with the same config is reused; one that was stopped (Ctrl-C, SIGTERM,
a killed process) is resumed from its latest checkpoint; one whose config differs is
refused unless ``overwrite`` retrains it. So a benchmark stopped at any point loses no
finished training, and running it again continues where it stopped.

Every learned model (one per seed) and every baseline is then evaluated with
:func:`~train.evaluate.episodes.run_episodes` on the same seeded episodes (one
evaluation seed, apart from the training seeds); the deterministic baselines are
evaluated once. :func:`~train.benchmark.stats.summarize_runs` turns the episodes into
the measures and their bootstrap intervals.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from swarm_envs.config import SwarmConfig, as_dict
from train.benchmark.matrix import Entry
from train.benchmark.stats import (
    BOOTSTRAP_SEED,
    CONFIDENCE,
    N_RESAMPLES,
    paired_difference,
    summarize_runs,
)
from train.config import TrainConfig, load_train_config
from train.evaluate.bound import bound_of_episodes, bound_reason, time_over_bound
from train.evaluate.harness import best_baseline
from train.evaluate.measures import finite

__all__ = [
    "DEFAULT_EPISODES",
    "DEFAULT_EVAL_SEED",
    "ModelRecord",
    "Settings",
    "StaleModelError",
    "evaluate_entry",
    "existing_run",
    "model_folder",
    "quick_overrides",
    "run_entry",
    "train_seed",
]

#: Seed of the evaluation episodes unless ``--eval-seed`` says otherwise.
DEFAULT_EVAL_SEED = 2026
#: Evaluation episodes per policy unless ``--episodes`` says otherwise: enough that an
#: effect carried by rare episodes (one stalled or lost in a hundred) is measured, not
#: sampled once or twice.
DEFAULT_EPISODES = 2000

Log = Callable[[str], None]


class StaleModelError(ValueError):
    """A model folder holds a run of another config than the one asked for."""


@dataclass(frozen=True)
class Settings:
    """How the entries are run: seeds, episodes, evaluation seed, bootstrap."""

    seeds: tuple[int, ...] = (0, 1, 2)
    episodes: int = DEFAULT_EPISODES
    eval_seed: int = DEFAULT_EVAL_SEED
    quick: bool = False
    overwrite: bool = False
    progress: bool = True
    n_resamples: int = N_RESAMPLES
    bootstrap_seed: int = BOOTSTRAP_SEED
    confidence: float = CONFIDENCE
    baselines_only: bool = False
    """Evaluate the baselines only: nothing is trained, no learned policy is reported."""
    jobs: int = 1
    """Processes at once: each training run and each entry's evaluation in a process of
    its own (1: everything in this process, one after another;
    :mod:`train.benchmark.parallel`)."""

    def to_dict(self) -> dict[str, Any]:
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["seeds"] = list(self.seeds)
        return out


@dataclass(frozen=True)
class ModelRecord:
    """A trained model of one seed: its path and how it came to be."""

    seed: int
    path: Path
    action: str  # "trained", "resumed" or "reused"
    timesteps: int
    train_seconds: float | None

    def to_dict(self) -> dict[str, Any]:
        return {
            "seed": self.seed,
            "path": str(self.path),
            "action": self.action,
            "timesteps": self.timesteps,
            "train_seconds": self.train_seconds,
        }


def quick_overrides(tc: TrainConfig) -> dict[str, Any]:
    """TrainConfig overrides of a smoke run of ``tc``: two swarms, about one update.

    PPO: one rollout of 32 steps on every slot and one epoch over it; SAC: 16 vector
    steps, learning from the first, one gradient step each; ES: one generation of two
    candidates. The networks and the env
    stay as configured.
    """
    slots = 2 * (tc.swarm_config().n_agents if tc.mode == "shared" else 1)
    base: dict[str, Any] = {"n_swarms": 2, "eval_freq": 0, "checkpoint_freq": 0}
    if tc.algo == "ES":  # one generation of one antithetic pair
        return {**base, "total_timesteps": 1, "hyperparams": {"population": 2}}
    if tc.algo == "PPO":
        hyper = {"n_steps": 32, "batch_size": 64, "n_epochs": 1}
        return {**base, "total_timesteps": 32 * slots, "hyperparams": hyper}
    hyper = {"learning_starts": 0, "batch_size": 64, "gradient_steps": 1, "train_freq": 1}
    hyper["buffer_size"] = 16 * slots
    return {**base, "total_timesteps": 16 * slots, "hyperparams": hyper}


def entry_train_config(entry: Entry, seed: int, quick: bool) -> TrainConfig:
    """The training config of ``entry`` for ``seed`` (the smoke run's with ``quick``)."""
    tc = entry.train_config(seed)
    return entry.train_config(seed, quick_overrides(tc)) if quick else tc


def _read_meta(folder: Path) -> dict[str, Any]:
    try:
        return json.loads((folder / "meta.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}


def _differences(saved: TrainConfig, wanted: TrainConfig) -> list[str]:
    return [
        f"{f.name} ({getattr(saved, f.name)!r} there, {getattr(wanted, f.name)!r} now)"
        for f in fields(TrainConfig)
        if getattr(saved, f.name) != getattr(wanted, f.name)
    ]


def existing_run(tc: TrainConfig, folder: Path, *, overwrite: bool = False) -> str:
    """What to do with ``folder`` for the run ``tc``: ``"reuse"`` (a finished run of
    ``tc``), ``"resume"`` (a stopped run of ``tc`` with a checkpoint) or ``"train"``
    (nothing there, an unfinished run without checkpoint, or ``overwrite``).

    Raises:
        StaleModelError: ``folder`` holds a run of another config, or a residual policy
            whose baseline gains were tuned anew since (without ``overwrite``).
    """
    from train.checkpoints import checkpoint_timesteps, latest_checkpoint

    saved_config = folder / "train_config.yaml"
    if overwrite or not saved_config.is_file():
        return "train"
    try:
        saved = load_train_config(saved_config)
    except ValueError as err:
        raise StaleModelError(
            f"{folder} holds an unreadable run ({err}); use --overwrite"
        ) from None
    diff = _differences(saved, tc)
    if diff:
        raise StaleModelError(
            f"{folder} holds a model trained with another config: {'; '.join(diff)}; "
            "use --overwrite to retrain it, or another --out"
        )
    ckpt = latest_checkpoint(folder)
    finished = _read_meta(folder).get("status") == "completed" or (
        ckpt is not None and checkpoint_timesteps(ckpt) >= tc.total_timesteps
    )
    if finished and (folder / "model.zip").is_file():
        _check_residual_baseline(tc, folder / "model.zip")
        return "reuse"
    if ckpt is None:
        return "train"
    _check_residual_baseline(tc, ckpt / "model.zip")
    return "resume"


def _check_residual_baseline(tc: TrainConfig, model_path: Path) -> None:
    """Refuse a residual model whose baseline is not the one ``tc`` trains on today: its
    config may be unchanged while ``swarm-tune`` has since rewritten the baseline's gains
    (``configs/baselines/tuned.yaml``). The model's baseline is the one it rebuilds from
    its record (:func:`train.residual.as_policy`), so a record older than a gain compares
    with the value that gain had then.

    Raises:
        StaleModelError: the baseline, its gains or the scale differ from today's.
    """
    if tc.residual is None or not model_path.is_file():
        return
    from train.evaluate.policies import load_sb3_model
    from train.residual import RESIDUAL, ResidualPolicy, make_baseline, residual_record

    policy = load_sb3_model(model_path)
    if not isinstance(policy, ResidualPolicy):
        raise StaleModelError(
            f"{model_path.parent} holds a policy without a baseline, where `{tc.residual}` "
            "is asked for; use --overwrite to retrain it, or another --out"
        )
    name = getattr(policy, RESIDUAL)["baseline"]
    there = residual_record(name, policy.baseline, policy.scale)
    today = residual_record(
        tc.residual, make_baseline(tc.residual, tc.swarm_config()), tc.residual_scale
    )
    if there != today:
        gains = sorted(
            k
            for k in set(there["gains"]) | set(today["gains"])
            if there["gains"].get(k) != today["gains"].get(k)
        )
        what = f"gains {', '.join(gains)}" if gains else "baseline or scale"
        raise StaleModelError(
            f"{model_path.parent} holds a residual policy on `{name}` whose {what} differ "
            f"from today's tuned `{tc.residual}` (configs/baselines/tuned.yaml); use "
            "--overwrite to retrain it, or another --out"
        )


def train_seed(
    tc: TrainConfig,
    folder: Path,
    *,
    overwrite: bool = False,
    progress: bool = True,
    tensorboard: bool = True,
    log: Log = print,
) -> ModelRecord:
    """Train ``tc`` into ``folder``, or reuse or resume the run already there
    (:func:`existing_run`).

    Raises:
        StaleModelError: ``folder`` holds a run of another config (without
            ``overwrite``).
        TrainingInterrupted: stopped by SIGINT/SIGTERM (the run is saved; running
            again resumes it).
    """
    from train.train import train

    action = existing_run(tc, folder, overwrite=overwrite)
    if action == "reuse":
        log(f"  seed {tc.seed}: reusing {folder / 'model.zip'}")
    else:
        verb = "resuming" if action == "resume" else "training"
        log(f"  seed {tc.seed}: {verb} {tc.algo} for {tc.total_timesteps:,} timesteps")
        train(
            tc,
            folder,
            progress_bar=progress,
            tensorboard=tensorboard,
            verbose=0,
            overwrite=action == "train",
            resume=action == "resume",
            prog="swarm-benchmark",
        )
    meta = _read_meta(folder)
    return ModelRecord(
        tc.seed,
        folder / "model.zip",
        {"reuse": "reused", "resume": "resumed", "train": "trained"}[action],
        int(meta.get("timesteps", 0)),
        meta.get("train_seconds"),
    )


@dataclass(frozen=True)
class _Episodes:
    """One policy's evaluation episodes, one value per episode."""

    returns: np.ndarray
    success: np.ndarray
    steps: np.ndarray
    reached: np.ndarray
    """The step of first success (the episode's length where it never succeeds)."""
    bound: np.ndarray | None
    """The lower bound on the time to goal of each start; ``None`` where undefined."""


def _episodes(policy: Any, cfg: SwarmConfig, s: Settings, name: str) -> _Episodes:
    from train.evaluate.episodes import run_episodes

    batch = run_episodes(
        policy, cfg, s.episodes, s.eval_seed, name=name, progress=False, record_episode=False
    )
    reached = batch.lengths if batch.first_success is None else batch.first_success
    bound = bound_of_episodes(cfg, batch.start)
    return _Episodes(batch.returns, batch.success, batch.lengths, reached, bound)


def _policy_result(
    runs: Sequence[_Episodes], cfg: SwarmConfig, s: Settings, **extra: Any
) -> dict[str, Any]:
    """The measures, intervals and per-episode values of ``runs`` (one per seed)."""
    arrays = {
        "return": np.stack([r.returns for r in runs]),
        "success": np.stack([r.success for r in runs]),
        "steps": np.stack([r.steps for r in runs]),
        "reached": np.stack([r.reached for r in runs]),
    }
    summary = summarize_runs(
        arrays["return"],
        arrays["success"],
        arrays["reached"],  # the time to goal: to the first step of success
        cfg.dt,
        n_resamples=s.n_resamples,
        seed=s.bootstrap_seed,
        confidence=s.confidence,
    )
    per_episode = {
        "return": arrays["return"].tolist(),
        "success": arrays["success"].astype(bool).tolist(),
        "steps": arrays["steps"].astype(int).tolist(),
    }
    bound = runs[0].bound
    over = time_over_bound(arrays["reached"] * cfg.dt, arrays["success"], bound)
    return {**extra, **summary, "time_over_bound": over, "per_episode": per_episode}


def evaluate_entry(
    entry: Entry,
    tc: TrainConfig,
    models: Sequence[ModelRecord],
    s: Settings,
    log: Log = print,
) -> list[dict[str, Any]]:
    """Evaluate every model of ``models`` and every baseline of ``entry`` in each of its
    evaluations; one result per evaluation, its policies' measures keyed by name
    (``learned`` and the baselines' names)."""
    import torch

    from agents import analytic_name, make_controller
    from train.evaluate.policies import TRAINED_ENV, load_sb3_model, trained_env_differences

    if tc.torch_threads is not None:
        torch.set_num_threads(tc.torch_threads)
    loaded = [(m, load_sb3_model(m.path, device=tc.device)) for m in models]
    results = []
    for ev in entry.evaluations:
        cfg = entry.eval_config(ev, tc)
        log(f"  evaluation {ev.label!r}: {s.episodes} episodes (seed {s.eval_seed})")
        notes = sorted(
            {
                d
                for _, model in loaded
                for d in trained_env_differences(getattr(model, TRAINED_ENV, None), cfg)
            }
        )
        started = time.perf_counter()
        runs = [_episodes(model, cfg, s, f"learned seed {m.seed}") for m, model in loaded]
        policies = {}
        if runs:
            policies["learned"] = _policy_result(
                runs, cfg, s, kind="learned", seeds=[m.seed for m, _ in loaded], notes=notes
            )
        baseline_runs: dict[str, _Episodes] = {}
        for name in expand_baselines(entry.baselines, cfg):
            controller = name if name != "analytic" else analytic_name(cfg)
            policy = make_controller(controller, cfg, seed=s.eval_seed)
            run = _episodes(policy, cfg, s, name)
            baseline_runs[name] = run
            policies[name] = _policy_result([run], cfg, s, kind="baseline", controller=controller)
        best = best_baseline(
            {
                n: {
                    "mean_return": policies[n]["return"]["value"],
                    "success_rate": policies[n]["success"]["value"],
                }
                for n in baseline_runs
            }
        )
        assert best is not None
        if runs:
            policies["learned"]["minus_best"] = {
                "baseline": best,
                "return": paired_difference(
                    np.stack([r.returns for r in runs]),
                    baseline_runs[best].returns,
                    n_resamples=s.n_resamples,
                    seed=s.bootstrap_seed,
                    confidence=s.confidence,
                ),
            }
        bound = baseline_runs[best].bound  # the same starts for every policy
        results.append(
            {
                "label": ev.label,
                "env": ev.env,
                "dt": cfg.dt,
                "max_steps": cfg.max_steps,
                "n_agents": cfg.n_agents,
                "config": as_dict(cfg),
                "eval_seconds": round(time.perf_counter() - started, 3),
                "best_baseline": best,
                "time_to_goal_bound": None if bound is None else finite(bound.mean()),
                "bound_undefined": bound_reason(cfg),
                "policies": policies,
            }
        )
    return results


def expand_baselines(names: Sequence[str], cfg: SwarmConfig) -> list[str]:
    """The baselines of an entry: ``names`` with ``"simple"`` replaced by the task's
    simple controllers (:data:`agents.SIMPLE`), each controller once, in order
    (``"analytic"`` stands for the controller it names: the mill's is its simple one).

    >>> from swarm_envs.tasks import task_config
    >>> expand_baselines(["analytic", "simple"], task_config("informed"))
    ['analytic', 'pd', 'follow']
    >>> expand_baselines(["analytic", "simple", "zero"], task_config("mill"))
    ['analytic', 'zero']
    """
    from agents import SIMPLE, analytic_name

    out: list[str] = []
    controllers: set[str] = set()
    for name in names:
        for item in SIMPLE[cfg.task] if name == "simple" else (name,):
            controller = analytic_name(cfg) if item == "analytic" else item
            if controller not in controllers:
                controllers.add(controller)
                out.append(item)
    return out


def model_folder(out: Path, entry: Entry, seed: int) -> Path:
    """``OUT/models/<entry name>/seed<k>``."""
    return out / "models" / Path(*entry.name.split("/")) / f"seed{seed}"


def run_entry(
    entry: Entry,
    out: Path,
    s: Settings,
    log: Log = print,
    trained: dict[int, ModelRecord] | None = None,
) -> dict[str, Any]:
    """Train (or reuse) the models of every seed of ``entry``, evaluate them and its
    baselines; the entry's results (see :mod:`train.benchmark.report`). ``trained``:
    the records of runs already trained for this entry, by seed (``--jobs``), used
    instead of training here."""
    log(f"{entry.name}: task {entry.task}, dynamics {entry.dynamics}, train {entry.train}")
    configs = [entry_train_config(entry, seed, s.quick) for seed in s.seeds]
    models = (
        []
        if s.baselines_only
        else [trained[seed] for seed in s.seeds]
        if trained is not None
        else [
            train_seed(
                tc,
                model_folder(out, entry, tc.seed),
                overwrite=s.overwrite,
                progress=s.progress,
                tensorboard=not s.quick,
                log=log,
            )
            for tc in configs
        ]
    )
    train_config = configs[0].to_dict()
    train_config.pop("seed")
    return {
        "name": entry.name,
        "task": entry.task,
        "dynamics": entry.dynamics,
        "train": entry.train,
        "env": entry.env,
        "train_overrides": entry.train_overrides,
        "train_config": train_config,
        "models": [m.to_dict() for m in models],
        "evaluations": evaluate_entry(entry, configs[0], models, s, log),
    }
