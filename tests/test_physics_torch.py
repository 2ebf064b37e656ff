"""The social potential physics on torch tensors: the same definitions as on numpy arrays,
the same numbers, compiled or plain.

docs/models.md §1 (forces, energy, Euler step): coincident agents, ``F = −∇V``,
momentum; and the compile switch of ``swarm_envs._runtime.torch_compile`` (automatic,
overridable, falling back to plain torch). Only one test compiles (small shapes); the
others run plain torch.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from swarm_envs._runtime import torch_compile as rt
from swarm_envs.physics import (
    SocialPotentialParams,
    energy,
    forces,
    potential_energy,
    random_swarm,
    step,
)

PARAMS = [
    SocialPotentialParams(),
    SocialPotentialParams.navigation(),
    SocialPotentialParams(C_o=0.0, beta=0.0, C_g=2.0, m=2.0),
]


def swarm(n: int, dim: int = 2, batch: tuple[int, ...] = (3,), seed: int = 0):
    x, v = random_swarm(
        np.random.default_rng(seed), n, dim=dim, radius=2.0, speed=0.5, batch_shape=batch
    )
    goal = np.random.default_rng(seed + 1).normal(size=(*batch, dim)) * 3
    return x, v, goal


@pytest.mark.parametrize("params", PARAMS)
@pytest.mark.parametrize("dim", [2, 3])
def test_forces_energy_and_step_match_numpy_in_float64(params, dim):
    x, v, goal = swarm(7, dim)
    tx, tv, tg = (torch.from_numpy(a) for a in (x, v, goal))
    np.testing.assert_allclose(
        forces(tx, tv, params, tg).numpy(), forces(x, v, params, goal), rtol=1e-12, atol=1e-12
    )
    np.testing.assert_allclose(
        energy(tx, tv, params, tg).numpy(), energy(x, v, params, goal), rtol=1e-12
    )
    u = np.random.default_rng(2).uniform(-1, 1, x.shape)
    x1, v1 = step(x, v, params, dt=0.05, goal=goal, control=u)
    tx1, tv1 = step(tx, tv, params, dt=0.05, goal=tg, control=torch.from_numpy(u))
    np.testing.assert_allclose(tx1.numpy(), x1, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(tv1.numpy(), v1, rtol=1e-12, atol=1e-12)


def test_float32_stays_float32_and_matches_numpy():
    params = SocialPotentialParams.navigation()
    x, v, _ = swarm(10, batch=(4,))
    x32, v32 = x.astype(np.float32), v.astype(np.float32)
    f = forces(torch.from_numpy(x32), torch.from_numpy(v32), params)
    assert f.dtype == torch.float32
    np.testing.assert_allclose(f.numpy(), forces(x32, v32, params), rtol=1e-5, atol=1e-5)


def test_cohesion_is_minus_the_gradient_of_the_pair_potential():
    params = SocialPotentialParams(C_o=0.0, beta=0.0, C_g=3.0)
    x, _, goal = swarm(6, batch=(2,))
    tx, tg = torch.from_numpy(x), torch.from_numpy(goal)
    f = forces(tx, torch.zeros_like(tx), params, tg)
    h = 1e-6
    grad = torch.zeros_like(tx)
    for i in range(x.shape[-2]):
        for k in range(x.shape[-1]):
            step_ = torch.zeros_like(tx)
            step_[..., i, k] = h
            up = potential_energy(tx + step_, params, tg)
            down = potential_energy(tx - step_, params, tg)
            grad[..., i, k] = (up - down) / (2 * h)
    np.testing.assert_allclose(f.numpy(), -grad.numpy(), rtol=1e-6, atol=1e-7)


def test_pair_forces_conserve_momentum():
    params = SocialPotentialParams(beta=0.0)  # cohesion + alignment are antisymmetric
    x, v, _ = swarm(9)
    f = forces(torch.from_numpy(x), torch.from_numpy(v), params)
    assert float(f.sum(-2).abs().max()) < 1e-12


def test_coincident_agents_give_finite_forces_and_energy():
    params = SocialPotentialParams.navigation()
    x = torch.zeros(2, 4, 2, dtype=torch.float32)  # every pair coincident
    x[1, 1] = 1e-12
    v = torch.randn(2, 4, 2, generator=torch.Generator().manual_seed(0))
    f = forces(x, v, params, goal=torch.zeros(2, 2))
    assert torch.isfinite(f).all()
    assert torch.isfinite(energy(x, v, params, torch.zeros(2, 2))).all()
    # u_ij = 0 for coincident pairs: no pair force, only dissipation.
    np.testing.assert_allclose(f[0].numpy(), (-params.beta * v[0]).numpy(), atol=1e-6)


def test_bad_input_raises_value_error():
    p = SocialPotentialParams()
    with pytest.raises(ValueError, match="positions must have shape"):
        forces(torch.zeros(3, 4), torch.zeros(3, 4), p)
    with pytest.raises(ValueError, match="velocities shape"):
        forces(torch.zeros(3, 2), torch.zeros(4, 2), p)
    with pytest.raises(ValueError, match="floating"):
        forces(torch.zeros(3, 2, dtype=torch.int64), torch.zeros(3, 2), p)
    with pytest.raises(ValueError, match="velocities must be a torch tensor"):
        forces(torch.zeros(3, 2), np.zeros((3, 2)), p)
    with pytest.raises(ValueError, match="goal must have shape"):
        forces(torch.zeros(3, 2), torch.zeros(3, 2), p, goal=torch.zeros(3))
    with pytest.raises(ValueError, match="dt must be"):
        rt.SocialPotentialStepper(p, dt=0.0)
    with pytest.raises(ValueError, match="SocialPotentialParams"):
        rt.SocialPotentialStepper({"C_a": 1.0}, dt=0.1)


# --------------------------------------------------------------------------- compiling


def test_resolve_compile_obeys_argument_and_environment(monkeypatch):
    monkeypatch.delenv(rt.COMPILE_ENV, raising=False)
    assert rt.resolve_compile(False) == (False, "compile=False")
    monkeypatch.setenv(rt.COMPILE_ENV, "0")
    assert rt.resolve_compile("auto")[0] is False
    monkeypatch.setenv(rt.COMPILE_ENV, "maybe")
    with pytest.raises(ValueError, match=rt.COMPILE_ENV):
        rt.resolve_compile("auto")
    monkeypatch.delenv(rt.COMPILE_ENV)
    with pytest.raises(ValueError, match="compile must be"):
        rt.resolve_compile("yes")
    monkeypatch.setattr(rt, "compile_support", lambda device="cpu": "no C++ compiler found")
    assert rt.resolve_compile("auto") == (False, "no C++ compiler found")
    with pytest.raises(ValueError, match="no C\\+\\+ compiler"):
        rt.resolve_compile(True)


def test_compile_support_names_what_is_missing(monkeypatch):
    monkeypatch.setenv("CXX", "")
    monkeypatch.setattr(rt.shutil, "which", lambda name: None)
    assert "C++ compiler" in rt.compile_support("cpu")
    assert rt.compile_support("meta") is not None


def test_auto_falls_back_to_plain_when_compiling_fails(monkeypatch):
    monkeypatch.delenv(rt.COMPILE_ENV, raising=False)
    monkeypatch.setattr(rt, "compile_support", lambda device="cpu": None)

    def broken_compile(fn, **kwargs):
        def run(*args, **kw):
            raise RuntimeError("simulated compiler failure")

        return run

    monkeypatch.setattr(torch, "compile", broken_compile)
    stepper = rt.SocialPotentialStepper(SocialPotentialParams(), dt=0.1)
    assert stepper.compiled
    x, v, _ = swarm(5, batch=(2,))
    tx, tv = torch.from_numpy(x), torch.from_numpy(v)
    with pytest.warns(UserWarning, match="falling back to plain torch"):
        x1, v1 = stepper.warmup(tx, tv)
    assert not stepper.compiled and stepper.compile_seconds is not None
    ref = step(tx, tv, SocialPotentialParams(), dt=0.1)
    assert torch.equal(x1, ref[0]) and torch.equal(v1, ref[1])
    # compile=True does not fall back: the failure surfaces.
    strict = rt.MaybeCompiled(lambda t: t, compile=True)
    with pytest.raises(RuntimeError, match="simulated"):
        strict.warmup(tx)


@pytest.mark.skipif(rt.compile_support("cpu") is not None, reason="torch.compile unavailable")
def test_compiled_step_matches_plain_step():
    params = SocialPotentialParams.navigation()
    x, v, goal = swarm(12, batch=(4,))
    args = [torch.from_numpy(a.astype(np.float32)) for a in (x, v, goal)]
    u = torch.from_numpy(np.random.default_rng(3).uniform(-3, 3, x.shape).astype(np.float32))
    plain = rt.SocialPotentialStepper(params, dt=0.1, compile=False)
    compiled = rt.SocialPotentialStepper(params, dt=0.1, compile=True)
    compiled.warmup(*args, u)
    assert compiled.compiled and compiled.compile_seconds > 0
    xp, vp = plain(*args, u)
    xc, vc = compiled(*args, u)
    torch.testing.assert_close(xc, xp, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(vc, vp, rtol=1e-5, atol=1e-5)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_matches_cpu():
    params = SocialPotentialParams.navigation()
    x, v, goal = swarm(16, batch=(8,))
    cpu = [torch.from_numpy(a.astype(np.float32)) for a in (x, v, goal)]
    gpu = [t.cuda() for t in cpu]
    stepper = rt.SocialPotentialStepper(params, dt=0.1, device="cuda")
    stepper.warmup(*gpu)
    xg, vg = stepper(*gpu)
    xc, vc = step(*cpu[:2], params, dt=0.1, goal=cpu[2])
    torch.testing.assert_close(xg.cpu(), xc, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(vg.cpu(), vc, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(
        energy(*gpu[:2], params, gpu[2]).cpu(), energy(*cpu[:2], params, cpu[2])
    )
