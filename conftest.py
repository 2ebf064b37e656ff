"""Shared pytest set-up (at the root, so every test path sees it): ``slow`` needs ``--runslow``."""

from __future__ import annotations

import importlib.util

import pytest

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
