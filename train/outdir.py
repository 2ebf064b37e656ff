"""Output folders: refuse to mix two runs in one folder.

A tool's ``--out`` may name a folder that does not exist yet or is empty. A non-empty
folder is refused unless ``--overwrite`` is given; then the files an earlier run of
these tools wrote there are removed first, so the folder never mixes two runs. Only
names these tools write are removed (:data:`TRAIN_FILES`, :data:`EVAL_FILES`,
:data:`SWEEP_FILES`); anything else in the folder is kept and reported.
``swarm-train --resume DIR`` is the one way to write into a run's folder again.
"""

from __future__ import annotations

import fnmatch
import shutil
from collections.abc import Iterable
from pathlib import Path

#: What ``swarm-train`` writes (SB3 and RLlib engines).
TRAIN_FILES = (
    "model.zip",
    "best_model.zip",
    "checkpoints",
    "checkpoint",
    "tensorboard",
    "train_config.yaml",
    "env_config.yaml",
    "meta.json",
    "progress.csv",
)
#: What ``swarm-eval`` writes (and ``report.md``, the demo's verdict on those results).
EVAL_FILES = ("results.json", "summary.md", "curves.png", "episode0_*.gif", "report.md")
#: What ``--overwrite`` clears before a training run (``swarm-train``, ``swarm-demo``):
#: an earlier run's training and evaluation outputs.
RUN_FILES = TRAIN_FILES + EVAL_FILES
#: What ``swarm-sweep`` writes.
SWEEP_FILES = (
    "trials.csv",
    "summary.csv",
    "results.json",
    "sweep.png",
    "sweep_config.yaml",
    "ray_tune",
)


class OutDirError(ValueError):
    """An output folder that cannot be used as asked."""


def check_out_dir(out: str | Path, *, overwrite: bool, flag: str = "--out") -> Path:
    """Check that ``out`` may receive a new run; writes nothing.

    Raises :class:`OutDirError` when ``out`` (or a folder above it) is a file, or when
    it is a non-empty folder and ``overwrite`` is false.
    """
    path = Path(out)
    for p in (path, *path.parents):
        if p.exists() and not p.is_dir():
            what = "is a file" if p == path else f"is below {p}, which is a file"
            raise OutDirError(f"{flag} {path} {what}; give a folder")
    try:
        occupied = path.is_dir() and any(path.iterdir())
    except OSError as err:
        raise OutDirError(f"{flag} {path} cannot be read: {err.strerror or err}") from None
    if occupied and not overwrite:
        raise OutDirError(
            f"{flag} {path} already holds files; choose a new folder, or add --overwrite "
            "to replace the earlier run there"
        )
    return path


def clear_previous_run(out: str | Path, patterns: Iterable[str]) -> tuple[list[str], list[str]]:
    """Remove the entries of ``out`` whose names match ``patterns``; create ``out``.

    Returns the names removed and the names kept, both sorted.
    """
    path = Path(out)
    path.mkdir(parents=True, exist_ok=True)
    patterns = tuple(patterns)
    removed, kept = [], []
    for entry in sorted(path.iterdir()):
        if any(fnmatch.fnmatchcase(entry.name, p) for p in patterns):
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink()
            removed.append(entry.name)
        else:
            kept.append(entry.name)
    return removed, kept


def prepare_out_dir(
    out: str | Path, *, overwrite: bool, patterns: Iterable[str], prog: str
) -> Path:
    """Create ``out`` for a new run; with ``overwrite``, first clear the earlier run there.

    Call :func:`check_out_dir` before any other work, and this once everything is
    validated. Prints one line when files are removed.
    """
    path = check_out_dir(out, overwrite=overwrite)
    try:
        if not overwrite or not path.is_dir():
            path.mkdir(parents=True, exist_ok=True)
            return path
        removed, kept = clear_previous_run(path, patterns)
    except OSError as err:
        raise OutDirError(f"cannot prepare --out {path}: {err.strerror or err}") from None
    if removed:
        note = f"; kept {len(kept)} other(s): {', '.join(kept[:5])}" if kept else ""
        more = ", ..." if len(kept) > 5 else ""
        print(
            f"{prog}: --overwrite: removed {len(removed)} earlier output(s) from {path}{note}{more}"
        )
    return path
