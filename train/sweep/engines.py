"""Running a sweep's trials: in this process (``local``) or as Ray Tune trials (``ray``).

Both engines run the same :func:`train.sweep.trials.run_trial` on the same specs, so
they give the same rows. Ray is imported only by :func:`run_ray`.
"""

from __future__ import annotations

import json
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from train.sweep.config import SweepConfig
from train.sweep.results import SweepResult, summarize_rows
from train.sweep.trials import run_trial

__all__ = ["ENGINES", "run_local", "run_ray", "run_sweep"]

ENGINES = ("local", "ray")


def run_local(specs: Sequence[Mapping[str, Any]], *, progress: bool = False) -> list[dict]:
    """Every trial in this process, one after another (no Ray). Rows in spec order."""
    from tqdm.auto import tqdm

    return [run_trial(s) for s in tqdm(specs, desc="trials", disable=not progress)]


def _tune_trial(config: dict[str, Any], specs: Sequence[Mapping[str, Any]]) -> None:
    """Ray Tune function trainable: one trial, reported as one JSON row (exact floats)."""
    from ray import tune

    row = run_trial(specs[config["index"]])
    tune.report({"index": row["index"], "row_json": json.dumps(row)})


def _progress_callback(total: int) -> Any:
    """A Ray Tune callback that advances a tqdm bar (stderr) as trials finish."""
    from ray.tune import Callback
    from tqdm.auto import tqdm

    class _Progress(Callback):
        def __init__(self) -> None:
            self.bar = tqdm(total=total, desc="trials", unit="trial")

        def on_trial_complete(self, iteration: int, trials: list, trial: Any, **info: Any) -> None:
            self.bar.update(1)

        def on_trial_error(self, iteration: int, trials: list, trial: Any, **info: Any) -> None:
            self.bar.update(1)

        def on_experiment_end(self, trials: list, **info: Any) -> None:
            self.bar.close()

    return _Progress()


def run_ray(
    specs: Sequence[Mapping[str, Any]],
    *,
    name: str = "sweep",
    address: str | None = None,
    num_cpus: int | None = None,
    cpus_per_trial: float = 1.0,
    max_concurrent_trials: int | None = None,
    storage_path: str | Path | None = None,
    progress: bool = False,
) -> list[dict]:
    """Every trial as a Ray Tune trial, on a local Ray or the cluster at ``address``.

    Args:
        specs: the trial specs (:meth:`SweepConfig.trial_specs`); Ray ships them once
            (``tune.with_parameters``) and each trial picks its own by index.
        name: Tune experiment name (a folder under ``storage_path``).
        address: a running Ray cluster (``HOST:PORT``, ``auto``); ``None`` starts a
            local Ray with ``num_cpus`` CPUs.
        num_cpus: CPUs of the local Ray (``None``: all).
        cpus_per_trial: CPUs Ray reserves per trial.
        max_concurrent_trials: cap on simultaneous trials (``None``: what CPUs allow).
        storage_path: where Tune keeps its per-trial logs (default ``~/ray_results``);
            on a multi-machine cluster a shared folder or a cloud URI. The rows come
            back to this process in any case.
        progress: a progress bar of finished trials (Tune's own tables stay off).

    Returns:
        The rows, in spec order.

    Raises:
        ImportError: Ray is not installed.
        RuntimeError: a trial failed (its error is included).
    """
    from train.rllib.cluster import ray_session, require_ray

    require_ray()
    with ray_session(address, num_cpus=num_cpus, verbose=progress):
        from ray import tune

        trainable = tune.with_resources(
            tune.with_parameters(_tune_trial, specs=list(specs)), {"cpu": cpus_per_trial}
        )
        run_config: dict[str, Any] = {"name": name, "verbose": 0}
        if progress:
            run_config["callbacks"] = [_progress_callback(len(specs))]
        if storage_path is not None:
            sp = str(storage_path)
            run_config["storage_path"] = sp if "://" in sp else str(Path(sp).resolve())
        tuner = tune.Tuner(
            trainable,
            param_space={"index": tune.grid_search(list(range(len(specs))))},
            tune_config=tune.TuneConfig(
                max_concurrent_trials=max_concurrent_trials, reuse_actors=True
            ),
            run_config=tune.RunConfig(**run_config),
        )
        grid = tuner.fit()
        if grid.errors:
            raise RuntimeError(f"{len(grid.errors)} sweep trial(s) failed; first: {grid.errors[0]}")
        rows = []
        for i in range(len(grid)):  # a ResultGrid is indexed (len, [i]): no iterator declared
            metrics = grid[i].metrics
            if metrics is None:
                raise RuntimeError(f"sweep trial {i} reported no result")
            rows.append(json.loads(metrics["row_json"]))
    rows.sort(key=lambda r: r["index"])
    if [r["index"] for r in rows] != [int(s["index"]) for s in specs]:
        raise RuntimeError("Ray Tune returned a different set of trials than it was given")
    return rows


def run_sweep(
    sc: SweepConfig,
    *,
    engine: str = "local",
    name: str = "sweep",
    address: str | None = None,
    num_cpus: int | None = None,
    storage_path: str | Path | None = None,
    progress: bool = False,
) -> SweepResult:
    """Run every trial of ``sc`` with ``engine`` (``local`` or ``ray``) and summarise.

    ``address``, ``num_cpus`` and ``storage_path`` apply to the ``ray`` engine
    (:func:`run_ray`).
    """
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {ENGINES}, got {engine!r}")
    if engine == "local" and address is not None:
        raise ValueError("address applies only to the ray engine")
    specs = sc.trial_specs()
    start = time.perf_counter()
    if engine == "local":
        rows = run_local(specs, progress=progress)
    else:
        rows = run_ray(
            specs,
            name=name,
            address=address,
            num_cpus=num_cpus,
            cpus_per_trial=sc.cpus_per_trial,
            max_concurrent_trials=sc.max_concurrent_trials,
            storage_path=storage_path,
            progress=progress,
        )
    seconds = time.perf_counter() - start
    return SweepResult(sc, engine, rows, summarize_rows(sc, rows), seconds)
