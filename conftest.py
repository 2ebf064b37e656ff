"""Shared pytest set-up (at the root, so every test path sees it).

* ``slow`` tests need ``--runslow``.
* Hermetic runs: every test runs in a fresh temporary working folder, so a tool's
  default output (``runs/eval``, ``runs/<config>``, ``reproductions``) lands there; and
  the session fails when the source tree holds files afterwards that it did not hold
  before (a test that wrote into the checkout).
"""

from __future__ import annotations

import importlib.util
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent
#: Entries the interpreter and the tools keep beside the sources.
_CACHES = ("__pycache__", ".pytest_cache", ".ruff_cache", ".hypothesis", ".egg-info")

#: ``train/benchmarl`` needs the ``benchmarl`` extra (``make install`` installs it);
#: without it, its modules are left out of the doctest collection.
collect_ignore = (
    []
    if importlib.util.find_spec("benchmarl")
    else ["train/benchmarl/torchrl_env.py", "train/benchmarl/task.py"]
)


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--runslow", action="store_true", default=False, help="also run tests marked slow"
    )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if config.getoption("--runslow"):
        return
    skip_slow = pytest.mark.skip(reason="slow: run with --runslow (make test-slow)")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip_slow)


@pytest.fixture(autouse=True)
def _work_in_a_temporary_folder(
    tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path_factory.mktemp("cwd"))


def untracked_files(root: Path = ROOT) -> set[str] | None:
    """The files and folders of ``root``'s git checkout that git does not track (ignored
    ones included, caches left out); ``None`` outside a git checkout."""
    try:
        proc = subprocess.run(
            ["git", "-C", str(root), "ls-files", "--others", "--directory", "-z"],
            capture_output=True,
            check=True,
            timeout=60,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    names = proc.stdout.decode(errors="replace").split("\0")
    return {n for n in names if n and not any(c in n for c in _CACHES)}


def pytest_sessionstart(session: pytest.Session) -> None:
    session.config.stash[_BEFORE] = untracked_files()


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    before = session.config.stash.get(_BEFORE, None)
    after = untracked_files()
    if before is None or after is None:
        return
    new = sorted(after - before)
    if new:
        print(f"\nthe tests wrote into the source tree {ROOT}: {', '.join(new)}")
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


_BEFORE = pytest.StashKey[set[str] | None]()
