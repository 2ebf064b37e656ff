"""What the command-line tools share: one-line errors with exit status 2.

Every user error of ``swarm-train``, ``swarm-eval``, ``swarm-demo`` and ``swarm-sweep``
is one line on stderr, ``<prog>: error: <what is wrong and what is allowed>``, and exit
status 2, whether argparse finds it (a bad flag value), the config loader (a YAML
syntax error, an unknown key, a value out of range) or the output-folder checks.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any, NoReturn

#: Exit status of a user error (a bad flag, config or output folder).
USAGE_ERROR = 2


class CliError(Exception):
    """A user error: reported as one line on stderr, exit status 2."""


class OneLineParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line (no usage block) and exit 2."""

    def error(self, message: str) -> NoReturn:
        print(f"{self.prog}: error: {one_line(message)} (see --help)", file=sys.stderr)
        sys.exit(USAGE_ERROR)


def one_line(text: str) -> str:
    """``text`` with its line breaks and runs of spaces folded into single spaces."""
    return " ".join(str(text).split())


def fail(prog: str, err: BaseException | str) -> int:
    """Print ``err`` as ``prog``'s one-line error; return the exit status 2."""
    print(f"{prog}: error: {one_line(describe(err))}", file=sys.stderr)
    return USAGE_ERROR


def describe(err: BaseException | str) -> str:
    """The message of a user error, YAML syntax errors and OS errors included."""
    import yaml

    if isinstance(err, str):
        return err
    if isinstance(err, yaml.YAMLError):
        return yaml_message(err)
    if isinstance(err, OSError) and err.strerror:
        where = f" {err.filename}" if err.filename else ""
        return f"cannot access{where}: {err.strerror}"
    return str(err)


def yaml_message(err: Any, source: str | None = None) -> str:
    """A YAML syntax error as ``<file>: invalid YAML at line L, column C: <problem>``."""
    mark = getattr(err, "problem_mark", None) or getattr(err, "context_mark", None)
    name = source or (mark.name if mark is not None else None)
    where = f"{name}: " if name and not str(name).startswith("<") else ""
    problem = getattr(err, "problem", None) or getattr(err, "context", None) or str(err)
    at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
    return f"{where}invalid YAML{at}: {problem}"


def check_seed(flag: str, value: int) -> int:
    """A seed must be an integer in [0, 2**32 - 1] (what numpy's seeding accepts)."""
    if not 0 <= value <= 2**32 - 1:
        raise CliError(f"{flag} must be an integer in [0, 4294967295], got {value}")
    return value


def check_device(flag: str, device: str) -> str:
    """A torch device name that this machine has (``cpu``, ``cuda``, ``cuda:1``, ...)."""
    from train.config import device_problem

    problem = device_problem(device)
    if problem is not None:
        raise CliError(f"{flag} {problem}")
    return device
