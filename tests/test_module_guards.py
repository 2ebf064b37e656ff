"""The compiled torch step checks the module objects it reads when a core is built.

:class:`~swarm_envs._runtime.module_guards.ModuleGuards` drops TorchDynamo's per-call
guards on module-level objects and checks them once, when a core with the same
configuration would share the compiled function. These tests show that a replaced
library function is still seen by the next core built, that guards on the arguments
are kept, and the parser of guard sources.
"""

from __future__ import annotations

import dataclasses
import math
import types

import numpy as np
import pytest

from swarm_envs._runtime.module_guards import ModuleGuards, _path
from swarm_envs._runtime.torch_compile import MaybeCompiled, compile_support
from swarm_envs.config import SwarmConfig

needs_compile = pytest.mark.skipif(
    compile_support("cpu") is not None, reason="torch.compile unavailable"
)


def test_guard_sources_are_read_up_to_what_can_be_checked():
    assert _path("G['m'].f[0]['k'].g") == (
        "m",
        (("attr", "f"), ("item", 0), ("item", "k"), ("attr", "g")),
    )
    # Dunder attributes give a new object at each access: the path stops before them.
    assert _path("dict(G['Frame'].__dict__)['__new__'].__func__") == ("Frame", ())
    assert _path("L['x']") is None


def test_a_replaced_module_object_is_seen():
    module = types.SimpleNamespace(pi=math.pi, f=math.sqrt, table=(math.exp,))
    guards = ModuleGuards({"mod": module})
    for source in ("G['mod'].pi", "G['mod'].f", "G['mod'].table[0]"):
        guards.note(source)
    assert guards.unchanged()
    module.table = (math.log,)
    assert not guards.unchanged()
    module.table = (math.exp,)  # the same object again
    assert guards.unchanged()
    del module.f
    assert not guards.unchanged()


def test_a_guard_that_cannot_be_read_is_never_trusted():
    guards = ModuleGuards({})
    guards.note("___check_obj_id(L['x'], 1)")
    assert not guards.unchanged()


def test_the_filter_keeps_the_guards_on_arguments_and_global_state():
    def entry(guard_type: str, name: str, is_global: bool) -> types.SimpleNamespace:
        return types.SimpleNamespace(guard_type=guard_type, name=name, is_global=is_global)

    guards = ModuleGuards({"math": math})
    entries = [
        entry("TENSOR_MATCH", "L['x']", False),
        entry("DUPLICATE_INPUT", "L['x']", False),
        entry("CONSTANT_MATCH", "L['cfg'].dt", False),
        entry("GRAD_MODE", "", False),
        entry("GLOBAL_STATE", "", True),
        entry("BUILTIN_MATCH", "G['math'].exp", True),
        entry("CONSTANT_MATCH", "G['math'].pi", True),
    ]
    assert guards.filter(entries) == [True] * 5 + [False] * 2
    assert guards.unchanged()


def test_an_unknown_choice_is_refused():
    with pytest.raises(ValueError, match="module_guards must be 'call' or 'build'"):
        MaybeCompiled(lambda x: x, compile=False, module_guards="never")


@needs_compile
def test_a_replaced_reward_reaches_the_next_compiled_core(monkeypatch):
    from swarm_envs.envs import torch_step
    from swarm_envs.envs.task import reward as shared_reward
    from swarm_envs.envs.torch_core import TorchSwarmNavCore

    cfg = SwarmConfig(n_agents=5, n_neighbors=2, max_steps=50)
    actions = np.random.default_rng(1).uniform(-1, 1, (2, 5, 2))

    def first_reward() -> np.ndarray:
        core = TorchSwarmNavCore(cfg, batch=2, compile=True)
        assert core.compiled
        core.reset(np.random.default_rng(0))
        return core.step(actions)[0]

    right = first_reward()
    np.testing.assert_array_equal(first_reward(), right)  # shared: the same function

    def doubled(weights, inputs):
        return shared_reward(dataclasses.replace(weights, time=2 * weights.time), inputs)

    monkeypatch.setattr(torch_step, "reward", doubled)
    np.testing.assert_allclose(first_reward(), right - cfg.reward.time, rtol=1e-5, atol=1e-6)
    monkeypatch.undo()
    np.testing.assert_array_equal(first_reward(), right)
