"""Train an SB3 policy on SwarmNav from a :class:`~train.config.TrainConfig`.

Two modes:

* ``shared`` (default): one policy for every agent. The env is
  ``swarm_nav_v0.vec_env(n_swarms, ...)``, a native batched VecEnv with one slot per
  agent; all swarms step in one array call (no SuperSuit, no per-env loop).
* ``central``: one policy sees the whole swarm (flat observation, flat action) through
  ``gymnasium.make(env_id)``, ``n_swarms`` copies in a ``DummyVecEnv``.

What a run writes into its output folder: ``model.zip`` (the latest saved model: final
once ``meta.json`` says ``completed``), ``best_model.zip`` (best periodic evaluation, if
enabled), ``checkpoints/step_<timesteps>/`` (the latest ``checkpoint_keep``; see
:mod:`train.checkpoints`), ``train_config.yaml``, ``env_config.yaml`` (the resolved env
configuration), ``meta.json`` (package versions, seed, ``status``: ``running``,
``interrupted`` or ``completed``, the timesteps ``model.zip`` holds, timings, torch's
thread count, and ``env``: the dynamics and the observation layout and size the model
was trained on, which every saved model zip also holds) and
``tensorboard/``. ``swarm-eval --config <out>/env_config.yaml --policies potential
<out>/model.zip`` evaluates it.

Checkpoints are taken between updates (the start of a rollout): every
``checkpoint_seconds`` of wall time (default 120: a killed run loses at most that, plus
one rollout and update, whatever the config's speed) and/or every ``checkpoint_freq``
timesteps, when a stop is requested (SIGINT, SIGTERM: :mod:`train.interrupt`) and at
the end. A stop is honoured at the next boundary, so after at most one rollout and one
update (and a periodic evaluation, if one is running).

Resuming (``resume=True``) loads the latest checkpoint: networks, optimizer, step count,
last observations, the replay buffer (SAC), the pickled training env (swarm states
mid-episode, its generator) and the generators SB3 draws from, then continues with
``reset_num_timesteps=False`` up to ``total_timesteps``. On the same machine and
software a resumed run gives the same model as an uninterrupted one, bit for bit (the
tests check PPO and SAC). What does not carry over: a stop discards the rollout in
progress (PPO) or the vector step in progress (SAC), which the resumed run collects
again from the same state; the logged timings (fps) restart, and SB3's logging
interval counts iterations from the resume; with ``use_sde``
the exploration noise drawn at the stopped rollout's start is drawn again, so that
run differs from then on; an env that cannot be pickled restarts its episodes (a
warning says so); a resumed run with a larger ``total_timesteps`` equals an
uninterrupted run of that total (the configs' schedules are constant).

Reproducibility: the same config and seed give the same model on the same machine and
software versions (CPU). Limits: results differ across torch/numpy versions and CPU
instruction sets (reductions may be vectorised differently), and on GPUs unless torch's
deterministic algorithms are enabled; ``torch_threads`` fixes the thread count, which
torch's CPU kernels may otherwise choose per machine.
"""

from __future__ import annotations

import contextlib
import functools
import json
import platform
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import yaml

import swarm_envs
from swarm_envs.config import as_dict
from train.callbacks import (
    AnalyticBaselineEvalCallback,
    ProgressLines,
    RunGuard,
    SwarmStatsCallback,
)
from train.checkpoints import (
    CHECKPOINTS,
    checkpoint_timesteps,
    copy_atomic,
    latest_checkpoint,
    load_checkpoint,
    save_checkpoint,
    write_atomic,
)
from train.config import POLICY, TrainConfig, algorithm_class
from train.es import ES
from train.evaluate.policies import TRAINED_ENV, trained_env_record
from train.interrupt import StopRequest, TrainingInterrupted, stop_on_signals
from train.outdir import RUN_FILES, check_out_dir, prepare_out_dir

if TYPE_CHECKING:
    import gymnasium as gym
    from stable_baselines3.common.base_class import BaseAlgorithm
    from stable_baselines3.common.vec_env import VecEnv

#: Where the output is not a terminal, ``progress_bar`` prints a line this often instead.
PROGRESS_LINE_SECONDS = 30.0


class TrainSetupError(ValueError):
    """A run that cannot start: SB3 rejects the config, or there is nothing to resume.

    Raised before anything is written.
    """


def make_training_env(tc: TrainConfig) -> VecEnv:
    """The VecEnv a run trains on, reporting SB3's ``episode`` infos.

    Shared mode: the batched ``SwarmNavVecEnv`` itself (it reports the episodes; a
    ``VecMonitor`` would add a Python loop over all B·N infos per step). Central mode:
    the gym envs in a ``DummyVecEnv`` under ``VecMonitor``.
    """
    from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor

    if tc.mode == "shared":
        venv = swarm_envs.swarm_nav_v0.vec_env(tc.n_swarms, config=tc.env_config, **tc.env)
        venv.seed(tc.seed)
        if tc.residual is not None:
            from train.residual import ResidualVecEnv, make_baseline

            baseline = make_baseline(tc.residual, tc.swarm_config())
            return ResidualVecEnv(venv, baseline, tc.residual_scale)
        return venv
    import gymnasium as gym

    def make_one() -> gym.Env:
        return gym.make(tc.env_id, config=tc.env_config, **tc.env)

    envs = DummyVecEnv([make_one for _ in range(tc.n_swarms)])
    envs.seed(tc.seed)
    return VecMonitor(envs)


@functools.cache
def done_slots_only(cls: type[BaseAlgorithm]) -> type[BaseAlgorithm]:
    """SB3 algorithm ``cls`` whose episode bookkeeping visits the slots that ended only.

    SB3's ``_update_info_buffer`` reads ``info.get("episode")`` and ``"is_success"`` of
    every slot on every step: with one slot per agent (32,768 slots at 1,024 swarms × 32
    agents) that loop costs more per step than the env's whole step. Monitors
    (``Monitor``, ``VecMonitor`` and ``SwarmNavVecEnv``) put ``episode`` into the infos
    of ended episodes only, and SB3 counts ``is_success`` only there, so visiting those
    slots keeps what it logs.
    Models save and load as ``cls`` (the override holds no state).
    """

    def _update_info_buffer(
        self: BaseAlgorithm, infos: list[dict[str, Any]], dones: np.ndarray | None = None
    ) -> None:
        if dones is None:
            return cls._update_info_buffer(self, infos, dones)
        ended = np.flatnonzero(dones)
        cls._update_info_buffer(self, [infos[i] for i in ended], np.ones(ended.size, bool))

    # type(name, bases, namespace) makes a class from a base only known at run time.
    subclass = type(
        cls.__name__,
        (cls,),
        {
            "_update_info_buffer": _update_info_buffer,
            "__module__": __name__,
            "__doc__": cls.__doc__,
        },
    )
    return cast("type[BaseAlgorithm]", subclass)


def build_model(tc: TrainConfig, venv: VecEnv, tensorboard_log: str | None = None) -> BaseAlgorithm:
    """The SB3 model of ``tc`` on ``venv`` (seeded; hyperparameters from the config).

    The model records the env it trains on as its
    :data:`~train.evaluate.policies.TRAINED_ENV` attribute, which SB3 saves with it.
    """
    cls = done_slots_only(algorithm_class(tc.algo))
    net = list(tc.net_arch)
    policy_kwargs: dict[str, Any] = {"net_arch": net if tc.algo == "SAC" else dict(pi=net, vf=net)}
    if tc.residual is not None and tc.algo == "PPO":
        policy_kwargs["log_std_init"] = tc.residual_log_std
    if tc.encoder is not None:
        from train.encoders import NeighborSetEncoder, encoder_kwargs

        policy_kwargs["features_extractor_class"] = NeighborSetEncoder
        policy_kwargs["features_extractor_kwargs"] = encoder_kwargs(
            tc.swarm_config(), tc.encoder_width
        )
    model = cls(
        POLICY,
        venv,
        seed=tc.seed,
        device=tc.device,
        policy_kwargs=policy_kwargs,
        tensorboard_log=tensorboard_log,
        verbose=0,
        **dict(tc.hyperparams),
    )
    # Saved in the zip's data (every model.zip, checkpoint and best_model.zip), set on load.
    setattr(model, TRAINED_ENV, trained_env_record(tc.swarm_config(), tc.env_id))
    if tc.residual is not None:
        from train.residual import RESIDUAL, ResidualVecEnv, residual_record

        if not isinstance(venv, ResidualVecEnv):
            raise TypeError(
                "a residual policy trains on a ResidualVecEnv (make_training_env), "
                f"got {type(venv).__name__}"
            )
        setattr(model, RESIDUAL, residual_record(tc.residual, venv.baseline, venv.scale))
    return model


def train(
    tc: TrainConfig,
    out_dir: str | Path,
    *,
    progress_bar: bool = True,
    tensorboard: bool = True,
    verbose: int = 1,
    overwrite: bool = False,
    resume: bool = False,
    stop: StopRequest | None = None,
    handle_signals: bool = True,
    prog: str = "swarm-train",
) -> Path:
    """Train according to ``tc``; write the model and its metadata into ``out_dir``.

    Returns the path of the final ``model.zip``.

    Args:
        progress_bar: show progress: SB3's bar on a terminal, else (a log file, no
            ``tqdm``/``rich``) a line every :data:`PROGRESS_LINE_SECONDS`
            (:class:`train.callbacks.ProgressLines`).
        overwrite: ``out_dir`` may hold an earlier run: its files are removed first
            (:func:`train.outdir.prepare_out_dir`). Without it a non-empty ``out_dir``
            raises :class:`train.outdir.OutDirError`.
        resume: continue the run in ``out_dir`` from its latest checkpoint (``tc`` is
            its config, :func:`train.config.resume_config`), up to ``tc.total_timesteps``.
        stop: asks the run to stop (see :mod:`train.interrupt`); with ``handle_signals``
            SIGINT and SIGTERM set it while training runs (main thread only).

    Raises:
        TrainSetupError: SB3 rejects the config, or ``resume`` finds nothing to
            continue; raised before anything is written.
        OutDirError: ``out_dir`` is a file, or holds files and ``overwrite`` is false.
        TrainingInterrupted: the run stopped on request after saving a checkpoint,
            ``model.zip`` and ``meta.json``.
    """
    import torch

    out = Path(out_dir)
    stop = stop if stop is not None else StopRequest()
    if not resume:
        check_out_dir(out, overwrite=overwrite)
    if tc.torch_threads is not None:
        torch.set_num_threads(tc.torch_threads)
    if tc.algo == ES:
        return _train_es(
            tc, out, progress_bar, verbose, overwrite, resume, stop, handle_signals, prog
        )
    tb = str(out / "tensorboard") if tensorboard and _has_tensorboard() else None
    if resume:
        model, state = _resume_model(tc, out, tb)
    else:
        model, state = _new_model(tc, tb), {"train_seconds": 0.0, "evaluator": None}
        prepare_out_dir(out, overwrite=overwrite, patterns=RUN_FILES, prog=prog)
    cfg = _write_run_configs(tc, out)
    run = _Run(tc, out, model, float(state["train_seconds"]))
    callbacks: list[Any] = [SwarmStatsCallback(cfg)]
    if tc.residual is not None and tc.residual_warmup > 0:
        from train.residual import CriticWarmup

        callbacks.append(CriticWarmup(tc.residual_warmup))
    if tc.eval_freq > 0:
        run.evaluator = AnalyticBaselineEvalCallback(
            cfg, tc.eval_freq, tc.eval_episodes, tc.eval_seed, out, verbose=verbose
        )
        if state["evaluator"] is not None:
            run.evaluator.load_state(state["evaluator"])
        callbacks.append(run.evaluator)
    bar = progress_bar and _has_progress_bar() and sys.stdout.isatty()
    if progress_bar and not bar:  # a log, not a terminal: a line every 30 s
        callbacks.append(ProgressLines(tc.total_timesteps, PROGRESS_LINE_SECONDS))
    guard = RunGuard(
        run.checkpoint,
        lambda: stop.requested,
        callbacks,
        every_seconds=tc.checkpoint_seconds,
        every_steps=tc.checkpoint_freq,
    )
    start_steps = model.num_timesteps
    run.write_meta("running")
    if verbose:
        what = f"resuming at {start_steps:,} timesteps" if resume else "training"
        print(
            f"{what} {tc.algo} ({tc.mode}) for {tc.total_timesteps:,} timesteps on "
            f"{model.n_envs} slots; N = {cfg.n_agents}; out = {out}"
        )
    guards = stop_on_signals(stop) if handle_signals else contextlib.nullcontext(stop)
    with guards:
        run.start_clock()
        model.learn(
            total_timesteps=tc.total_timesteps - start_steps,
            callback=guard,
            progress_bar=bar,
            tb_log_name=tc.algo,
            reset_num_timesteps=not resume,
        )
        if guard.stopped:
            assert guard.last_checkpoint is not None and stop.signum is not None
            run.publish(guard.last_checkpoint, "interrupted")
            model.get_env().close()
            raise TrainingInterrupted(
                stop.signum, checkpoint_timesteps(guard.last_checkpoint), out, guard.last_checkpoint
            )
        final = guard.checkpoint()  # after the last update: a boundary, as ever
        run.publish(final, "completed")
    model.get_env().close()
    if verbose:
        print(f"saved {out / 'model.zip'} after {run.train_seconds():.0f} s")
    return out / "model.zip"


def _train_es(
    tc: TrainConfig,
    out: Path,
    progress_bar: bool,
    verbose: int,
    overwrite: bool,
    resume: bool,
    stop: StopRequest,
    handle_signals: bool,
    prog: str,
) -> Path:
    """:func:`train` for ``algo: ES`` (:mod:`train.es`): the same output folder."""
    from train.es import train_es

    if resume:
        _resume_checkpoint(tc, out)  # there is one, short of total_timesteps
    else:
        prepare_out_dir(out, overwrite=overwrite, patterns=RUN_FILES, prog=prog)
    _write_run_configs(tc, out)
    return train_es(
        tc,
        out,
        progress_bar=progress_bar,
        verbose=verbose,
        resume=resume,
        stop=stop,
        handle_signals=handle_signals,
    )


def _write_run_configs(tc: TrainConfig, out: Path) -> Any:
    """Write ``train_config.yaml`` and ``env_config.yaml`` into ``out``; return the
    resolved :class:`~swarm_envs.config.SwarmConfig`."""
    cfg = tc.swarm_config()
    (out / "train_config.yaml").write_text(yaml.safe_dump(tc.to_dict(), sort_keys=False))
    (out / "env_config.yaml").write_text(yaml.safe_dump(as_dict(cfg), sort_keys=False))
    return cfg


def _resume_checkpoint(tc: TrainConfig, out: Path) -> Path:
    """The latest checkpoint in ``out``, to continue up to ``tc.total_timesteps``.

    Raises:
        TrainSetupError: there is none, or it holds ``total_timesteps`` already.
    """
    ckpt = latest_checkpoint(out)
    if ckpt is None:
        raise TrainSetupError(
            f"--resume {out}: no checkpoint in {out / CHECKPOINTS} to continue from"
        )
    done = checkpoint_timesteps(ckpt)
    if done >= tc.total_timesteps:
        raise TrainSetupError(
            f"--resume {out}: the run has {done:,} timesteps, total_timesteps is "
            f"{tc.total_timesteps:,}; give a larger total_timesteps=... to extend it"
        )
    return ckpt


def _new_model(tc: TrainConfig, tensorboard_log: str | None) -> Any:
    """A fresh model of ``tc`` on its training env; SB3's own refusals as ValueError
    (``algo: ES``: the PPO model whose actor it trains, :func:`train.es.policy_model`)."""
    if tc.algo == ES:
        from train.es import policy_model

        return policy_model(tc)
    venv = make_training_env(tc)
    try:
        return build_model(tc, venv, tensorboard_log=tensorboard_log)
    except (AssertionError, ValueError, TypeError) as err:
        venv.close()
        raise TrainSetupError(f"{tc.algo} rejects the config: {err}") from None


def _resume_model(tc: TrainConfig, out: Path, tensorboard_log: str | None) -> tuple[Any, dict]:
    """The model of the latest checkpoint in ``out`` and its saved state."""
    ckpt = _resume_checkpoint(tc, out)
    cls = done_slots_only(algorithm_class(tc.algo))
    try:
        return load_checkpoint(
            ckpt,
            cls,
            device=tc.device,
            make_env=lambda: make_training_env(tc),
            tensorboard_log=tensorboard_log,
        )
    except Exception as err:  # a damaged or foreign checkpoint: say which, not a traceback
        raise TrainSetupError(
            f"--resume {out}: cannot load checkpoint {ckpt} ({type(err).__name__}: {err}); "
            "move it away to resume from the one before"
        ) from err


class _Run:
    """The bookkeeping of one run: checkpoints, ``model.zip``, ``meta.json``, timings."""

    def __init__(self, tc: TrainConfig, out: Path, model: Any, seconds_before: float) -> None:
        self.tc = tc
        self.out = out
        self.model = model
        self.seconds_before = seconds_before
        self.evaluator: AnalyticBaselineEvalCallback | None = None
        self._clock = time.perf_counter()
        self.checkpoint_path: Path | None = None

    def start_clock(self) -> None:
        self._clock = time.perf_counter()

    def train_seconds(self) -> float:
        """Wall time spent training, earlier runs of a resumed run included."""
        return self.seconds_before + time.perf_counter() - self._clock

    def checkpoint(self) -> Path:
        """Save a checkpoint, then point ``model.zip`` and ``meta.json`` at it."""
        extra = {
            "train_seconds": round(self.train_seconds(), 3),
            "evaluator": self.evaluator.state() if self.evaluator is not None else None,
        }
        path = save_checkpoint(self.model, self.out, extra, keep=self.tc.checkpoint_keep)
        self.publish(path, "running")
        return path

    def publish(self, checkpoint: Path, status: str) -> None:
        """``model.zip`` ← the checkpoint's model; ``meta.json`` with ``status``."""
        copy_atomic(checkpoint / "model.zip", self.out / "model.zip")
        self.checkpoint_path = checkpoint
        self.write_meta(status)

    def write_meta(self, status: str) -> None:
        """``meta.json`` (:func:`run_meta`) with ``status`` and the periodic evaluations."""
        path = self.checkpoint_path
        meta = run_meta(
            self.tc,
            status,
            checkpoint_timesteps(path) if path else 0,
            str(path.relative_to(self.out)) if path else None,
            self.train_seconds(),
        )
        meta["evaluations"] = self.evaluator.history if self.evaluator is not None else []
        write_atomic(self.out / "meta.json", json.dumps(meta, indent=2) + "\n")


def run_meta(
    tc: TrainConfig, status: str, timesteps: int, checkpoint: str | None, train_seconds: float
) -> dict[str, Any]:
    """What ``meta.json`` says of a run: versions, the run's description, its progress.

    ``status`` is ``running`` (also what a killed run leaves), ``interrupted`` or
    ``completed``; ``timesteps`` and ``checkpoint`` (relative to the output folder)
    describe what ``model.zip`` holds.
    """
    import stable_baselines3
    import torch

    return {
        "swarm_envs": swarm_envs.__version__,
        "stable_baselines3": stable_baselines3.__version__,
        "torch": torch.__version__,
        "numpy": np.__version__,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "algo": tc.algo,
        "mode": tc.mode,
        "seed": tc.seed,
        "total_timesteps": tc.total_timesteps,
        "status": status,
        "timesteps": timesteps,
        "checkpoint": checkpoint,
        "train_seconds": round(train_seconds, 2),
        "torch_threads": torch.get_num_threads(),
        "env": {
            k: v
            for k, v in trained_env_record(tc.swarm_config(), tc.env_id).items()
            if k != "env_config"  # env_config.yaml holds it
        },
    }


def _has_tensorboard() -> bool:
    try:
        import tensorboard  # noqa: F401
    except ImportError:
        return False
    return True


def _has_progress_bar() -> bool:
    try:
        import rich  # noqa: F401
        import tqdm  # noqa: F401
    except ImportError:
        return False
    return True
