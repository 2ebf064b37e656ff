"""Train a benchmark's models in parallel processes (``swarm-benchmark --jobs J``).

Each (entry, seed) run is :func:`~train.benchmark.run.train_seed` in a process of its
own (started by ``spawn``, in its own process group), at most ``J`` at once; the
evaluations then run in the main process as without ``--jobs``, on the models these
runs left. The runs are the same as one after another: each is seeded by its config
alone, and each training process is told its torch threads by its config.

Stopping: SIGINT or SIGTERM to the main process starts no further run and is passed
on, once, to every running one, which saves and stops as ``swarm-train`` does (a
second signal is passed on too, and aborts them without saving). The training
processes are in their own process groups, so a Ctrl-C in the terminal reaches them
only through the main process, once. The main process then raises the
:class:`~train.interrupt.TrainingInterrupted` of the first run that stopped; running
the same command again reuses the finished runs and resumes the stopped ones.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import queue
import signal
from collections.abc import Sequence
from pathlib import Path
from types import FrameType
from typing import Any

from train.benchmark.matrix import Entry
from train.benchmark.run import Log, ModelRecord, entry_train_config, model_folder, train_seed

__all__ = ["train_in_parallel"]

#: How often (seconds) the main process looks at its training processes.
_POLL_SECONDS = 0.2


def _train_job(
    key: tuple[str, int],
    entry: Entry,
    seed: int,
    out: Path,
    quick: bool,
    overwrite: bool,
    results: Any,
) -> None:
    """One run in a training process: its outcome goes to ``results`` as ``(key, kind,
    value)``, ``kind`` one of ``"done"`` (a :class:`ModelRecord`), ``"stopped"`` (the
    interruption's ``signum, timesteps, out, checkpoint``) or ``"failed"`` (the error's
    type name and message)."""
    from train.interrupt import TrainingAborted, TrainingInterrupted

    os.setpgrp()  # a terminal's Ctrl-C reaches this run through the main process only
    try:
        tc = entry_train_config(entry, seed, quick)
        record = train_seed(
            tc,
            model_folder(out, entry, seed),
            overwrite=overwrite,
            progress=False,
            tensorboard=not quick,
            log=lambda line: print(f"{entry.name} {line.strip()}", flush=True),
        )
        results.put((key, "done", record))
    except TrainingInterrupted as err:
        results.put((key, "stopped", (err.signum, err.timesteps, err.out, err.checkpoint)))
    except TrainingAborted as err:
        results.put((key, "aborted", err.signum))
    except Exception as err:  # reported by the main process, which raises it
        results.put((key, "failed", (type(err).__name__, str(err))))


def train_in_parallel(
    entries: Sequence[Entry],
    seeds: Sequence[int],
    out: Path,
    *,
    jobs: int,
    quick: bool,
    overwrite: bool,
    log: Log = print,
) -> dict[tuple[str, int], ModelRecord]:
    """Train (or reuse, or resume) every entry's model of every seed, ``jobs`` at once;
    ``{(entry name, seed): record}``.

    Raises:
        TrainingInterrupted: a stop signal reached the main process; the runs saved.
        TrainingAborted: a second stop signal; the running runs stopped without saving.
        RuntimeError: a run failed (its error's type and message).
    """
    from train.interrupt import TrainingAborted, TrainingInterrupted

    ctx = mp.get_context("spawn")
    results = ctx.Queue()
    pending = [(entry, seed) for entry in entries for seed in seeds]
    running: dict[tuple[str, int], Any] = {}
    records: dict[tuple[str, int], ModelRecord] = {}
    stopped: list[tuple[Any, ...]] = []
    failures: list[str] = []
    signals: list[int] = []
    aborted: int | None = None

    def forward(signum: int, frame: FrameType | None) -> None:
        signals.append(signum)
        for process in running.values():
            if process.pid is not None and process.is_alive():
                os.kill(process.pid, signum)

    stop_signals = (signal.SIGINT, signal.SIGTERM)
    previous = {s: signal.signal(s, forward) for s in stop_signals}
    log(f"training {len(pending)} runs, {jobs} at once")
    try:
        while pending or running:
            while pending and len(running) < jobs and not signals and not failures:
                entry, seed = pending.pop(0)
                key = (entry.name, seed)
                process = ctx.Process(
                    target=_train_job,
                    args=(key, entry, seed, out, quick, overwrite, results),
                    name=f"{entry.name}/seed{seed}",
                )
                process.start()
                running[key] = process
            if (signals or failures) and not running:
                break
            try:
                key, kind, value = results.get(timeout=_POLL_SECONDS)
            except queue.Empty:
                for key, process in list(running.items()):
                    if not process.is_alive() and results.empty():
                        process.join()
                        failures.append(
                            f"{key[0]} seed {key[1]}: the training process ended "
                            f"(exit status {process.exitcode}) without a result"
                        )
                        del running[key]
                continue
            running.pop(key).join()
            if kind == "done":
                records[key] = value
            elif kind == "stopped":
                stopped.append(value)
            elif kind == "aborted":
                aborted = value
            else:
                failures.append(f"{key[0]} seed {key[1]}: {value[0]}: {value[1]}")
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
    if aborted is not None:
        raise TrainingAborted(aborted)
    if stopped:
        signum, timesteps, folder, checkpoint = stopped[0]
        raise TrainingInterrupted(signum, timesteps, Path(folder), Path(checkpoint))
    if failures:
        raise RuntimeError("; ".join(failures))
    if signals:  # stopped while no run was training: nothing to save
        raise KeyboardInterrupt
    return records
