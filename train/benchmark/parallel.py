"""Train and evaluate a benchmark's entries in parallel processes (``swarm-benchmark
--jobs J``).

Each (entry, seed) run is :func:`~train.benchmark.run.train_seed` in a process of its
own (started by ``spawn``, in its own process group), and each entry's evaluation,
:func:`~train.benchmark.run.run_entry` on the models its runs left, is one more such
process, started as soon as the entry's runs are trained: at most ``J`` processes at
once, an evaluation that is ready before the next training run. The runs are the same
as one after another: each is seeded by its config alone, and each training and
evaluation process is told its torch threads by its config; the evaluations are those
of one process (the same episodes, the same bootstrap).

Stopping: SIGINT or SIGTERM to the main process starts no further process and is
passed on, once, to every running one: a training run saves and stops as
``swarm-train`` does (a second signal is passed on too, and aborts it without
saving), an evaluation stops without a result. The processes are in their own process
groups, so a Ctrl-C in the terminal reaches them only through the main process, once.
The main process then raises the :class:`~train.interrupt.TrainingInterrupted` of the
first run that stopped; running the same command again reuses the finished runs,
resumes the stopped ones and evaluates every entry again.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import queue
import signal
from collections.abc import Callable, Sequence
from pathlib import Path
from types import FrameType
from typing import Any

from train.benchmark.matrix import Entry
from train.benchmark.run import (
    Log,
    ModelRecord,
    Settings,
    entry_train_config,
    model_folder,
    run_entry,
    train_seed,
)

__all__ = ["run_in_parallel"]

#: How often (seconds) the main process looks at its training processes.
_POLL_SECONDS = 0.2


def _train_job(
    key: tuple[str, int | None],
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


def _cancel(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt


def _evaluate_job(
    key: tuple[str, int | None],
    entry: Entry,
    out: Path,
    settings: Settings,
    trained: dict[int, ModelRecord],
    results: Any,
) -> None:
    """One entry's evaluation in a process of its own: ``(key, "evaluated", its
    results)``, ``(key, "cancelled", None)`` when a stop signal reached it, or ``(key,
    "failed", ...)``."""
    os.setpgrp()
    signal.signal(signal.SIGTERM, _cancel)  # as SIGINT: stop without a result
    try:
        result = run_entry(
            entry,
            out,
            settings,
            log=lambda line: print(
                line if line.startswith(entry.name) else f"{entry.name} {line.strip()}",
                flush=True,
            ),
            trained=trained,
        )
        results.put((key, "evaluated", result))
    except KeyboardInterrupt:
        results.put((key, "cancelled", None))
    except Exception as err:
        results.put((key, "failed", (type(err).__name__, str(err))))


def run_in_parallel(
    entries: Sequence[Entry],
    out: Path,
    settings: Settings,
    *,
    written: Callable[[list[dict[str, Any]]], None],
    log: Log = print,
) -> list[dict[str, Any]]:
    """Train (or reuse, or resume) every entry's model of every seed of ``settings``
    and evaluate every entry, ``settings.jobs`` processes at once; the entries'
    results in the order of ``entries``. ``written`` is called with the results of
    the entries evaluated so far (in that order) each time one more is.

    Raises:
        TrainingInterrupted: a stop signal reached the main process; the runs saved.
        TrainingAborted: a second stop signal; the running runs stopped without saving.
        KeyboardInterrupt: a stop signal while no run was training.
        RuntimeError: a run or an evaluation failed (its error's type and message).
    """
    from train.interrupt import TrainingAborted, TrainingInterrupted

    s, jobs = settings, settings.jobs
    ctx = mp.get_context("spawn")
    results = ctx.Queue()
    pending = [(entry, seed) for entry in entries for seed in s.seeds]
    ready: list[Entry] = []  # entries whose runs are all trained, not yet evaluated
    running: dict[tuple[str, int | None], Any] = {}
    records: dict[tuple[str, int], ModelRecord] = {}
    evaluated: dict[str, dict[str, Any]] = {}
    stopped: list[tuple[Any, ...]] = []
    failures: list[str] = []
    signals: list[int] = []
    aborted: int | None = None

    def forward(signum: int, frame: FrameType | None) -> None:
        signals.append(signum)
        for process in running.values():
            if process.pid is not None and process.is_alive():
                os.kill(process.pid, signum)

    def start_next() -> None:
        if ready:  # an evaluation first: its results are written as soon as it ends
            entry = ready.pop(0)
            key: tuple[str, int | None] = (entry.name, None)
            trained = {seed: records[entry.name, seed] for seed in s.seeds}
            target: Any = _evaluate_job
            args: tuple[Any, ...] = (key, entry, out, s, trained, results)
            name = f"{entry.name}/evaluate"
        else:
            entry, seed = pending.pop(0)
            key = (entry.name, seed)
            target = _train_job
            args = (key, entry, seed, out, s.quick, s.overwrite, results)
            name = f"{entry.name}/seed{seed}"
        process = ctx.Process(target=target, args=args, name=name)
        process.start()
        running[key] = process

    def what(key: tuple[str, int | None]) -> str:
        return f"{key[0]} {'evaluation' if key[1] is None else f'seed {key[1]}'}"

    stop_signals = (signal.SIGINT, signal.SIGTERM)
    previous = {sig: signal.signal(sig, forward) for sig in stop_signals}
    runs = f"{len(pending)} run{'s' * (len(pending) != 1)}"
    evaluations = f"{len(entries)} entr{'ies' if len(entries) != 1 else 'y'}"
    log(f"training {runs} and evaluating {evaluations}, {jobs} at once")
    try:
        while pending or ready or running:
            while (pending or ready) and len(running) < jobs and not signals and not failures:
                start_next()
            if (signals or failures) and not running:
                break
            try:
                key, kind, value = results.get(timeout=_POLL_SECONDS)
            except queue.Empty:
                for key, process in list(running.items()):
                    if not process.is_alive() and results.empty():
                        process.join()
                        failures.append(
                            f"{what(key)}: the process ended (exit status {process.exitcode}) "
                            "without a result"
                        )
                        del running[key]
                continue
            running.pop(key).join()
            if kind == "done":
                name, seed = key
                assert seed is not None
                records[name, seed] = value
                entry = next(e for e in entries if e.name == name)
                if all((name, k) in records for k in s.seeds):
                    ready.append(entry)
            elif kind == "evaluated":
                evaluated[key[0]] = value
                written([evaluated[e.name] for e in entries if e.name in evaluated])
            elif kind == "stopped":
                stopped.append(value)
            elif kind == "aborted":
                aborted = value
            elif kind == "failed":
                failures.append(f"{what(key)}: {value[0]}: {value[1]}")
            # "cancelled": an evaluation stopped by a signal; the next run evaluates again
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if aborted is not None:
        raise TrainingAborted(aborted)
    if stopped:
        signum, timesteps, folder, checkpoint = stopped[0]
        raise TrainingInterrupted(signum, timesteps, Path(folder), Path(checkpoint))
    if failures:
        raise RuntimeError("; ".join(failures))
    if signals:  # stopped while no run was training: nothing to save
        raise KeyboardInterrupt
    return [evaluated[e.name] for e in entries]
