"""Every shell command of README.md's ```bash blocks is run here, or listed with a reason.

The commands run in README order in one empty working folder, as a reader would type
them (``runs/demo`` written by one command is read by the next), each through its
console script's ``main`` (``[project.scripts]`` of ``pyproject.toml``), in-process:

* fast: each ``swarm-train`` command exactly as written with the training itself
  replaced by building the model (every check of the command line, the config, its
  overrides and the output folder runs), then every command in a tiny variant for
  real (:data:`TINY`: one rollout of one swarm, two evaluation episodes, ``--quick`` reproductions);
* slow (``--runslow``): every command exactly as written.

A command that is neither run (its program in :data:`TINY`) nor in :data:`NOT_RUN`
fails :func:`test_every_readme_command_is_run_or_listed`, and so does an entry of
:data:`NOT_RUN` that the README no longer holds.
"""

from __future__ import annotations

import contextlib
import importlib
import io
import re
import shlex
from collections.abc import Callable
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"

#: Commands not run here, each with the reason (keys: the command's words, joined by
#: single spaces, quotes removed).
NOT_RUN: dict[str, str] = {
    "make demo": "creates .venv and trains the full recipe; `swarm-demo` itself runs in "
    "tests/test_train.py (a smoke run, and the full demo with --runslow)",
    "make test": "runs this test suite",
    "make install": "installs packages into .venv (network)",
    "pip install -e .[dev]": "installs packages (network)",
    "pip install -e .[dev,distributed]": "installs packages (network)",
    "pip install -e .[dev,fast]": "installs packages (network)",
    "pip install -e .[dev,benchmarl]": "installs packages (network)",
    "swarm-tune": "rewrites the shipped configs/baselines/tuned.yaml (about an hour); "
    "tests/test_strong_baselines.py runs it on a tiny grid into a temporary file",
    "swarm-benchmark --baselines-only": "every baseline of the matrix on 2,000 episodes "
    "(minutes); tests/test_strong_baselines.py runs it on two entries",
    "tensorboard --logdir runs/ppo/tensorboard": "a web server that runs until stopped; "
    "the tiny run checks that the folder it reads exists",
    "make benchmark": "trains every entry of configs/benchmark/results.yaml with 3 seeds "
    "(hours); tests/test_benchmark.py runs swarm-benchmark --quick end to end",
    "make reproduce": "every paper at full size (= swarm-reproduce --out reproductions); "
    "the README's one-paper command runs here, tests/test_papers_cli.py runs the others",
}

#: Folders a listed command reads, checked to exist when its turn comes in the tiny run.
READS = {"tensorboard --logdir runs/ppo/tensorboard": "runs/ppo/tensorboard"}


def _train_tiny(argv: list[str]) -> list[str]:
    # Flags before the overrides (argparse ends the positional list at a flag).
    return [argv[0], "--no-progress", *argv[1:], "n_swarms=1", "total_timesteps=1", "eval_freq=0"]


def _eval_tiny(argv: list[str]) -> list[str]:
    out = list(argv)
    if "--episodes" in out:
        out[out.index("--episodes") + 1] = "2"
    else:
        out += ["--episodes", "2"]
    return [*out, "--no-gif", "--no-progress"]


def _demo_tiny(argv: list[str]) -> list[str]:
    return [
        argv[0],
        "--no-progress",
        "--episodes",
        "2",
        *argv[1:],
        "n_swarms=1",
        "total_timesteps=1",
    ]


#: Programs run here, and how their tiny variant is made from the README's words.
TINY: dict[str, Callable[[list[str]], list[str]]] = {
    "swarm-train": _train_tiny,
    "swarm-eval": _eval_tiny,
    "swarm-demo": _demo_tiny,
    "swarm-reproduce": lambda argv: [*argv, "--quick"],
}

#: Exit statuses a tiny variant may end with (a demo trained for one rollout does not
#: beat the analytic controller: 1).
TINY_OK = {"swarm-demo": (0, 1)}


def readme_commands(text: str) -> list[list[str]]:
    """The commands of the ```bash blocks of ``text``: words per command, comments and
    line continuations resolved."""
    commands = []
    for block in re.findall(r"^```bash\n(.*?)^```", text, flags=re.S | re.M):
        for line in block.replace("\\\n", " ").splitlines():
            words = shlex.split(line, comments=True)
            if words:
                commands.append(words)
    return commands


COMMANDS = readme_commands(README.read_text(encoding="utf-8"))


def _key(words: list[str]) -> str:
    return " ".join(words)


def _entry_point(program: str) -> Callable[[list[str]], int]:
    """The ``main`` of a console script, from ``[project.scripts]`` of pyproject.toml."""
    text = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    section = re.search(r"^\[project\.scripts\]\n(.*?)(?=^\[|\Z)", text, flags=re.S | re.M)
    assert section is not None, "pyproject.toml has no [project.scripts]"
    scripts = dict(re.findall(r'^([\w-]+)\s*=\s*"([^"]+)"', section.group(1), flags=re.M))
    module, _, func = scripts[program].partition(":")
    return getattr(importlib.import_module(module), func)


def _run(words: list[str]) -> tuple[int, str]:
    """Run a console-script command in-process: its exit status and its stderr."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            status = _entry_point(words[0])(words[1:])
        except SystemExit as exc:  # argparse
            status = exc.code if isinstance(exc.code, int) else 1
    return int(status or 0), err.getvalue().strip()


def _check_only(monkeypatch: pytest.MonkeyPatch) -> None:
    """``swarm-train`` without the training: the run's checks and the model are built."""
    import train.train as trainer
    from train.outdir import check_out_dir

    def build_only(tc, out, *, overwrite=False, resume=False, **_kw):
        if not resume:
            check_out_dir(Path(out), overwrite=overwrite)
            trainer._new_model(tc, None).get_env().close()
        return Path(out) / "model.zip"

    monkeypatch.setattr(trainer, "train", build_only)


def test_readme_has_commands():
    programs = {words[0] for words in COMMANDS}
    assert {"swarm-train", "swarm-eval", "make"} <= programs


def test_every_readme_command_is_run_or_listed():
    keys = {_key(words) for words in COMMANDS}
    unhandled = [k for k in keys if k not in NOT_RUN and k.split()[0] not in TINY]
    assert not unhandled, (
        f"README commands neither run by this test nor listed in NOT_RUN: {unhandled}"
    )
    stale = [k for k in NOT_RUN if k not in keys]
    assert not stale, f"NOT_RUN lists commands the README no longer has: {stale}"


#: The output folders of the listed commands a reader runs before the others.
NOT_RUN_OUT = {"make demo": "runs/demo", "make reproduce": "reproductions"}
#: The output folder of a program when its command names none.
DEFAULT_OUT = {
    "swarm-eval": lambda words: "runs/eval",
    "swarm-train": lambda words: f"runs/{Path(words[words.index('--config') + 1]).stem}",
    "swarm-reproduce": lambda words: "reproductions",
    "swarm-demo": lambda words: "runs/demo",
}


def _out(words: list[str]) -> str | None:
    key = _key(words)
    if key in NOT_RUN_OUT:
        return NOT_RUN_OUT[key]
    if "--out" in words:
        return words[words.index("--out") + 1]
    if words[0] in DEFAULT_OUT and "--resume" not in words:
        return DEFAULT_OUT[words[0]](words)
    return None


def test_no_two_readme_commands_write_one_folder():
    """Run in README order, every command gets a folder of its own: none is refused
    because an earlier one filled it (``--overwrite`` says a command means to)."""
    seen: dict[str, str] = {}
    for words in COMMANDS:
        out = _out(words)
        if out is None or "--overwrite" in words:
            continue
        assert out not in seen, f"{_key(words)!r} writes {out}, as {seen[out]!r} did before"
        seen[out] = _key(words)


def test_readme_commands_run_in_tiny_variants(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.chdir(tmp_path)
    failures = []
    for words in COMMANDS:
        key = _key(words)
        if key in NOT_RUN:
            if key in READS and not Path(READS[key]).exists():
                failures.append(f"{key}: {READS[key]} does not exist at this point")
            continue
        program = words[0]
        if program == "swarm-train":
            with monkeypatch.context() as m:
                _check_only(m)
                status, err = _run(words)
            if status != 0:
                failures.append(f"{key} (as written, without training): exit {status}: {err}")
                continue
        tiny = TINY[program](words)
        status, err = _run(tiny)
        if status not in TINY_OK.get(program, (0,)):
            failures.append(f"{_key(tiny)}: exit {status}: {err}")
    assert not failures, "README commands that fail:\n" + "\n".join(failures)


@pytest.mark.slow
def test_readme_commands_run_as_written(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.chdir(tmp_path)
    failures = []
    for words in COMMANDS:
        if _key(words) in NOT_RUN:
            continue
        status, err = _run(words)
        if status != 0:
            failures.append(f"{_key(words)}: exit {status}: {err}")
    assert not failures, "README commands that fail:\n" + "\n".join(failures)
