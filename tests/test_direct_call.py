"""Compiled functions called without TorchDynamo's per-call guards (``direct=True``).

:class:`~swarm_envs._runtime.direct_call.DirectCall` calls the graph that Dynamo chose
for a warmup call directly. These tests check that the mapping of arguments and outputs
gives Dynamo's results exactly, that functions it cannot map keep the guarded path (with
a warning), and that a replaced library function still reaches the next core built.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
import torch

from swarm_envs._runtime.torch_compile import MaybeCompiled, compile_support
from swarm_envs.config import SwarmConfig

pytestmark = pytest.mark.skipif(
    compile_support("cpu") is not None, reason="torch.compile unavailable"
)

OFFSET = torch.tensor([0.5, -0.25])


def _swapped(a: torch.Tensor, b: torch.Tensor, scale: torch.Tensor) -> tuple:
    # Outputs nested and in another order than the arguments are read.
    return (b * scale, (a + b, torch.exp(-a)))


def _reads_a_global(a: torch.Tensor) -> tuple:
    return (a + OFFSET,)


def _values(out):
    return [t.clone() for t in torch.utils._pytree.tree_flatten(out)[0]]


def test_a_direct_call_gives_the_guarded_results_for_any_values():
    fn = MaybeCompiled(_swapped, compile=True, name="test.swapped", direct=True)
    a, b, scale = torch.rand(3, 2), torch.rand(3, 2), torch.rand(3, 1)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        fn.warmup(a, b, scale)
    assert fn.direct
    for seed in range(3):
        g = torch.Generator().manual_seed(seed)
        args = (torch.rand(3, 2, generator=g), torch.rand(3, 2, generator=g), torch.rand(3, 1))
        got = fn(*args)
        assert isinstance(got, tuple) and isinstance(got[1], tuple)
        for mine, theirs in zip(_values(got), _values(fn._call(*args)), strict=True):
            assert torch.equal(mine, theirs)
        torch.testing.assert_close(got[0], args[1] * args[2])


def test_a_graph_that_reads_more_than_its_arguments_keeps_the_guards():
    fn = MaybeCompiled(_reads_a_global, compile=True, name="test.global", direct=True)
    with pytest.warns(UserWarning, match="test.global: the compiled graph is called through"):
        fn.warmup(torch.zeros(2))
    assert not fn.direct
    torch.testing.assert_close(fn(torch.ones(2))[0], torch.ones(2) + OFFSET)


def test_aliased_warmup_arguments_keep_the_guards():
    fn = MaybeCompiled(_swapped, compile=True, name="test.aliased", direct=True)
    a = torch.rand(3, 2)
    with pytest.warns(UserWarning, match="each tensor argument once"):
        fn.warmup(a, a, torch.rand(3, 1))
    assert not fn.direct


def test_the_core_calls_its_compiled_functions_directly_with_the_guarded_results():
    from swarm_envs.envs.cores.torch.core import TorchSwarmNavCore

    cfg = SwarmConfig(n_agents=6, n_neighbors=3, dt=0.3, max_substeps=4, max_steps=20)
    core = TorchSwarmNavCore(cfg, batch=64, dtype=np.float64, compile=True)
    assert core._advance.direct and core._substep.direct and core._advance_part.direct
    core.reset(np.random.default_rng(0))
    actions = np.random.default_rng(1).uniform(-1, 1, (64, 6, 2))
    args = core._args(core._to_device(actions), core._dt_each)
    for mine, theirs in zip(
        _values(core._advance(*args)), _values(core._advance._call(*args)), strict=True
    ):
        assert torch.equal(mine, theirs)


def test_a_replaced_reward_reaches_the_next_compiled_core(monkeypatch):
    from swarm_envs.envs.cores.torch import step as torch_step
    from swarm_envs.envs.cores.torch.core import TorchSwarmNavCore
    from swarm_envs.envs.task import reward as shared_reward

    cfg = SwarmConfig(n_agents=5, n_neighbors=2, max_steps=50)
    actions = np.random.default_rng(1).uniform(-1, 1, (2, 5, 2))

    def first_reward() -> np.ndarray:
        core = TorchSwarmNavCore(cfg, batch=2, compile=True)
        assert core.compiled and core._advance.direct
        core.reset(np.random.default_rng(0))
        return core.step(actions)[0]

    right = first_reward()
    np.testing.assert_array_equal(first_reward(), right)

    def doubled(weights, inputs):
        return shared_reward(dataclasses.replace(weights, time=2 * weights.time), inputs)

    monkeypatch.setattr(torch_step, "reward", doubled)
    np.testing.assert_allclose(first_reward(), right - cfg.reward.time, rtol=1e-5, atol=1e-6)
    monkeypatch.undo()
    np.testing.assert_array_equal(first_reward(), right)


def test_a_tensor_at_other_strides_is_read_in_the_traced_layout():
    # A permuted view of the same values (the layout torch.where keeps from an input):
    # the graph, traced for contiguous tensors, must still read the right elements.
    fn = MaybeCompiled(_swapped, compile=True, name="test.strides", direct=True)
    fn.warmup(torch.rand(2, 3), torch.rand(2, 3), torch.rand(2, 1))
    assert fn.direct
    a = torch.rand(3, 2).t()  # (2, 3) at strides (1, 2)
    b, scale = torch.rand(2, 3), torch.rand(2, 1)
    with pytest.warns(UserWarning, match="laid out otherwise than it was traced for"):
        got = fn(a, b, scale)
    for mine, theirs in zip(_values(got), _values(_swapped(a, b, scale)), strict=True):
        torch.testing.assert_close(mine, theirs)
    assert fn._direct.relaid == 1 and fn._direct.guarded == 0
    fn(a.contiguous(), b, scale)  # the traced layout: no copy
    assert fn._direct.relaid == 1


def test_a_tensor_of_another_shape_goes_through_the_guards():
    fn = MaybeCompiled(_swapped, compile=True, name="test.shape", direct=True)
    fn.warmup(torch.rand(2, 3), torch.rand(2, 3), torch.rand(2, 1))
    a, b, scale = torch.rand(4, 3), torch.rand(4, 3), torch.rand(4, 1)
    with pytest.warns(UserWarning, match="calling it through TorchDynamo's guards"):
        got = fn(a, b, scale)
    for mine, theirs in zip(_values(got), _values(_swapped(a, b, scale)), strict=True):
        torch.testing.assert_close(mine, theirs)
    assert fn._direct.guarded == 1
