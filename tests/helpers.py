"""Helpers shared by the env tests: strict warnings, global random generator snapshots."""

from __future__ import annotations

import contextlib
import random
import warnings
from collections.abc import Iterator
from typing import Any

import numpy as np
import torch

RngStates = tuple[Any, Any, torch.Tensor]


def rng_states() -> RngStates:
    """The global generators' states: numpy's legacy one, Python's and torch's."""
    return np.random.get_state(), random.getstate(), torch.get_rng_state()  # noqa: NPY002


def assert_same_rng_states(a: RngStates, b: RngStates) -> None:
    (np_a, py_a, torch_a), (np_b, py_b, torch_b) = a, b
    assert np_a[0] == np_b[0]
    assert np.array_equal(np_a[1], np_b[1])
    assert np_a[2:] == np_b[2:]
    assert py_a == py_b
    assert torch.equal(torch_a, torch_b)


#: The only warning allowed under :func:`strict_warnings`: ``render_mode="human"`` on a
#: headless machine (the checkers construct the env in every render mode).
NO_WINDOW = ".*could not open a window"


@contextlib.contextmanager
def strict_warnings() -> Iterator[None]:
    """Every warning is an error, except our own headless-window notice."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message=NO_WINDOW, category=UserWarning)
        yield
