"""Stopping a training run on SIGINT or SIGTERM without losing it.

The first SIGINT (Ctrl-C) or SIGTERM asks the run to stop: :class:`StopRequest` records
the signal, and the trainer stops at the next update boundary, saves a checkpoint,
``model.zip`` and ``meta.json``, and raises :class:`TrainingInterrupted`. The
command-line tools then print one line and exit with ``128 + signal number``: 130 for
SIGINT and 143 for SIGTERM, the shells' convention for a process ended by that
signal. A second signal before the run has stopped aborts at once without saving
(:class:`TrainingAborted`); the latest periodic checkpoint stays.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import FrameType

#: The signals that stop a run.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def signal_name(signum: int) -> str:
    """``SIGINT``, ``SIGTERM``, ..."""
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


def exit_status(signum: int) -> int:
    """The exit status of a run stopped by ``signum``: ``128 + signum``."""
    return 128 + signum


class StopRequest:
    """Whether a stop was asked for, and by which signal."""

    def __init__(self) -> None:
        self.signum: int | None = None

    @property
    def requested(self) -> bool:
        """True once a stop was asked for."""
        return self.signum is not None

    def request(self, signum: int = signal.SIGINT) -> None:
        """Ask the run to stop at its next update boundary."""
        if self.signum is None:
            self.signum = signum


class TrainingInterrupted(Exception):
    """A run stopped on request after saving everything it had."""

    def __init__(self, signum: int, timesteps: int, out: Path, checkpoint: Path) -> None:
        self.signum = signum
        self.timesteps = timesteps
        self.out = out
        self.checkpoint = checkpoint
        super().__init__(
            f"stopped by {signal_name(signum)} at {timesteps:,} timesteps; saved "
            f"{out / 'model.zip'} and {checkpoint}; continue with: swarm-train --resume {out}"
        )


class TrainingAborted(BaseException):
    """A second stop signal: the run ends at once without saving."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(
            f"{signal_name(signum)} again: aborted without saving; the latest periodic "
            "checkpoint, if any, remains"
        )


@contextmanager
def stop_on_signals(stop: StopRequest | None = None) -> Iterator[StopRequest]:
    """Within the block, SIGINT and SIGTERM set ``stop`` (a second one aborts).

    The previous handlers come back on exit. Outside the main thread, where Python
    cannot install handlers, the block runs with ``stop`` and no handlers.
    """
    stop = stop if stop is not None else StopRequest()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return

    def handler(signum: int, frame: FrameType | None) -> None:
        if stop.requested:
            raise TrainingAborted(signum)
        stop.request(signum)

    previous = {s: signal.signal(s, handler) for s in STOP_SIGNALS}
    try:
        yield stop
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
