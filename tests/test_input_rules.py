"""The input rule of docs/inputs.md on every API and every available backend.

APIs: the Gymnasium central env, the PettingZoo parallel env, the PettingZoo AEC env
(``swarm_nav_v0.env()``) and the SB3 VecEnv. Each refused action must raise a
``ValueError`` stating the rule and what was given, and leave the env as it was (the
next valid step equals a twin's that never saw the refused call); each accepted form
must step exactly like the float64 numpy array of the same values. Seeds and configs
likewise.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from swarm_envs import swarm_nav_v0
from swarm_envs.config import SwarmConfig
from swarm_envs.envs.adapters.swarm_nav import SwarmNavEnv
from swarm_envs.envs.backends import unsupported
from swarm_envs.physics import LagrangianParams

torch = pytest.importorskip("torch")

N, D, B = 4, 2, 2  # agents per swarm, dimension, swarms of the VecEnv
BACKENDS = ("numpy", "cutoff", "torch", "native")
ACTION_RULE = r"must be a real numeric array \(float or integer dtype; not bool, complex"
SEED_RULE = r"seed must be None or a non-negative integer"


def require(backend: str) -> None:
    """Skip where ``backend`` cannot run here (the C step not built, no torch...)."""
    why = unsupported(SwarmConfig(n_agents=N, backend=backend), backend)
    if why is not None:
        pytest.skip(f"backend {backend!r} unavailable here: {why}")


# --------------------------------------------------------------------------- the APIs


class Api:
    """One API, driven uniformly: ``unit`` is the shape of the action one call takes."""

    name: str
    unit: tuple[int, ...]

    def make(self, backend: str, **kwargs: Any) -> Any:
        raise NotImplementedError

    def reset(self, env: Any, seed: Any) -> np.ndarray:
        raise NotImplementedError

    def step(self, env: Any, action: Any) -> np.ndarray:
        """One step in which ``action`` is the tested one (the other agents' zero)."""
        raise NotImplementedError


class Gym(Api):
    name, unit = "gym", (N * D,)

    def make(self, backend: str, **kwargs: Any) -> Any:
        return SwarmNavEnv(n_agents=N, backend=backend, **kwargs)

    def reset(self, env: Any, seed: Any) -> np.ndarray:
        return env.reset(seed=seed)[0]

    def step(self, env: Any, action: Any) -> np.ndarray:
        return env.step(action)[0]


class Parallel(Api):
    name, unit = "parallel", (D,)
    agent = "agent_1"

    def make(self, backend: str, **kwargs: Any) -> Any:
        return swarm_nav_v0.parallel_env(n_agents=N, backend=backend, **kwargs)

    def reset(self, env: Any, seed: Any) -> np.ndarray:
        obs, _ = env.reset(seed=seed)
        return np.stack([obs[a] for a in env.possible_agents])

    def step(self, env: Any, action: Any) -> np.ndarray:
        actions = {a: np.zeros(D, np.float32) for a in env.agents}
        actions[self.agent] = action
        obs = env.step(actions)[0]
        return np.stack([obs[a] for a in env.possible_agents])


class Aec(Api):
    """The tested action is the first of a cycle: the parallel step runs only after the
    last agent's, so an error here shows the AEC env checks each action on its own."""

    name, unit = "aec", (D,)

    def make(self, backend: str, **kwargs: Any) -> Any:
        return swarm_nav_v0.env(n_agents=N, backend=backend, **kwargs)

    def reset(self, env: Any, seed: Any) -> np.ndarray:
        env.reset(seed=seed)
        return np.stack([env.observe(a) for a in env.possible_agents])

    def step(self, env: Any, action: Any) -> np.ndarray:
        env.step(action)
        for _ in range(N - 1):
            env.step(np.zeros(D, np.float32))
        return np.stack([env.observe(a) for a in env.possible_agents])


class Vec(Api):
    name, unit = "vec", (B * N, D)

    def make(self, backend: str, **kwargs: Any) -> Any:
        return swarm_nav_v0.vec_env(B, n_agents=N, backend=backend, **kwargs)

    def reset(self, env: Any, seed: Any) -> np.ndarray:
        env.seed(seed)
        return env.reset()

    def step(self, env: Any, action: Any) -> np.ndarray:
        return env.step(action)[0]


APIS = {api.name: api for api in (Gym(), Parallel(), Aec(), Vec())}
_PAIRS: dict[tuple[str, str], tuple[Any, Any]] = {}


def pair(api: Api, backend: str) -> tuple[Any, Any]:
    """Two envs of ``api`` on ``backend``, built once per module (compiling is slow)."""
    require(backend)
    key = (api.name, backend)
    if key not in _PAIRS:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # torch's deprecation notices while compiling
            _PAIRS[key] = (api.make(backend), api.make(backend))
    return _PAIRS[key]


api_param = pytest.mark.parametrize("api", list(APIS.values()), ids=list(APIS))
backend_param = pytest.mark.parametrize("backend", BACKENDS)


# --------------------------------------------------------------------------- refused actions


def _other_shapes(unit: tuple[int, ...]) -> dict[str, tuple[int, ...]]:
    """Shapes of the right size but another shape (transposed, flat, with an extra axis)."""
    size = int(np.prod(unit))
    shapes = {"column": (size, 1), "row": (1, size)}
    if len(unit) == 2:
        shapes |= {"transposed": unit[::-1], "flat": (size,)}
    elif unit == (N * D,):
        shapes |= {"agents_by_dim": (N, D), "dim_by_agents": (D, N)}
    return shapes


def refused_actions(unit: tuple[int, ...]) -> dict[str, Callable[[], Any]]:
    """Every kind of action the rule refuses, for an API whose action has shape ``unit``."""
    size = int(np.prod(unit))
    zeros = np.zeros(unit)
    longer = (*unit[:-1], unit[-1] + 1)

    def with_value(value: float) -> np.ndarray:
        a = np.zeros(unit)
        a.flat[size // 2] = value
        return a

    def list_with(item: Any) -> list:
        flat: list[Any] = [0.0] * size
        flat[-1] = item
        return np.array(flat, dtype=object).reshape(unit).tolist()

    cases: dict[str, Callable[[], Any]] = {
        "complex": lambda: np.full(unit, 0.5 + 0.5j),
        "complex_zero_imag": lambda: np.zeros(unit, np.complex64),
        "bool": lambda: np.ones(unit, bool),
        "object": lambda: zeros.astype(object),
        "str": lambda: np.full(unit, "0.5"),
        "bytes": lambda: np.full(unit, b"0"),
        "datetime": lambda: np.zeros(unit, "datetime64[s]"),
        "none": lambda: None,
        "python_float": lambda: 0.5,
        "numpy_scalar": lambda: np.float64(0.5),
        "dict": lambda: {"agent_0": zeros},
        "longer": lambda: np.zeros(longer),
        "shorter": lambda: np.zeros((*unit[:-1], unit[-1] - 1)),
        "empty": lambda: np.zeros((0,)),
        "list_with_bool": lambda: list_with(True),
        "list_with_str": lambda: list_with("0.5"),
        "list_with_complex": lambda: list_with(1j),
        "ragged_list": lambda: [*zeros.tolist(), [0.0]],
        "nan": lambda: with_value(np.nan),
        "inf": lambda: with_value(np.inf),
        "-inf": lambda: with_value(-np.inf),
        "tensor_complex": lambda: torch.zeros(unit, dtype=torch.complex64),
        "tensor_bool": lambda: torch.zeros(unit, dtype=torch.bool),
        "tensor_transposed": lambda: torch.zeros(unit[::-1] if len(unit) == 2 else (1, size)),
        "tensor_nan": lambda: torch.from_numpy(with_value(np.nan)),
    }
    for name, shape in _other_shapes(unit).items():
        cases[f"shape_{name}"] = lambda shape=shape: np.zeros(shape)
    return cases


REFUSED = [
    pytest.param(api, case, id=f"{api.name}-{case}")
    for api in APIS.values()
    for case in refused_actions(api.unit)
]


@backend_param
@pytest.mark.parametrize(("api", "case"), REFUSED)
def test_refused_action_raises_naming_the_rule_and_changes_nothing(
    api: Api, case: str, backend: str
):
    cases = refused_actions(api.unit)
    env, twin = pair(api, backend)
    api.reset(env, 7)
    api.reset(twin, 7)
    bad = cases[case]()
    with pytest.raises(ValueError) as err:
        api.step(env, bad)
    message = str(err.value)
    if "nan" in case or "inf" in case:
        assert re.search(r"finite \(got NaN or inf\); allowed range \[-1, 1\]", message)
    else:
        assert re.search(ACTION_RULE, message), message
        assert f"of shape {api.unit}, got" in message, message  # the rule, then what came
        if isinstance(bad, np.ndarray):  # what was given: its dtype and shape
            assert f"{bad.dtype} array of shape {bad.shape}" in message, message
    if api.name in ("parallel", "aec"):
        agent = Parallel.agent if api.name == "parallel" else "agent_0"
        assert message.startswith(f"action of {agent}"), message
    # Nothing moved: the next valid step is the twin's.
    valid = np.full(api.unit, 0.25)
    assert np.array_equal(api.step(env, valid), api.step(twin, valid))


# --------------------------------------------------------------------------- accepted actions


def _grid(unit: tuple[int, ...]) -> np.ndarray:
    """Values exact in float16 and bfloat16: multiples of 1/4 in [-1, 0.75]."""
    return ((np.arange(int(np.prod(unit))) % 8 - 4) / 4).reshape(unit)


def _ints(unit: tuple[int, ...]) -> np.ndarray:
    return (np.arange(int(np.prod(unit))) % 3 - 1).reshape(unit)


ACCEPTED: dict[str, tuple[Callable[[tuple[int, ...]], np.ndarray], Callable[[np.ndarray], Any]]] = {
    "float32": (_grid, lambda a: a.astype(np.float32)),
    "float16": (_grid, lambda a: a.astype(np.float16)),
    "non_contiguous": (_grid, lambda a: np.repeat(a, 2, axis=-1)[..., ::2]),
    "read_only": (_grid, lambda a: np.lib.stride_tricks.as_strided(a, writeable=False)),
    "list": (_grid, lambda a: a.tolist()),
    "tuple": (_grid, lambda a: tuple(map(tuple, a)) if a.ndim == 2 else tuple(a)),
    "int64": (_ints, lambda a: a.astype(np.int64)),
    "int8": (_ints, lambda a: a.astype(np.int8)),
    "uint8": (lambda u: np.abs(_ints(u)), lambda a: a.astype(np.uint8)),
    "int_list": (_ints, lambda a: a.astype(int).tolist()),
    "clipped": (lambda u: np.clip(3 * _grid(u), -1, 1), lambda a: 3 * _grid(a.shape)),
    "tensor_requires_grad": (
        _grid,
        lambda a: torch.tensor(a, dtype=torch.float32, requires_grad=True),
    ),
    "tensor_float64": (_grid, lambda a: torch.tensor(a)),
    "tensor_bfloat16": (_grid, lambda a: torch.tensor(a, dtype=torch.bfloat16)),
    "tensor_int64": (_ints, lambda a: torch.tensor(a, dtype=torch.int64)),
    "tensor_non_leaf": (_grid, lambda a: torch.tensor(a, requires_grad=True) * 1.0),
}


@pytest.mark.parametrize("case", list(ACCEPTED))
@backend_param
@api_param
def test_accepted_action_steps_as_its_float64_values(api: Api, backend: str, case: str):
    values, form = ACCEPTED[case]
    env, twin = pair(api, backend)
    api.reset(env, 3)
    api.reset(twin, 3)
    reference = values(api.unit).astype(np.float64)
    obs = api.step(env, form(reference))
    assert np.array_equal(obs, api.step(twin, reference))
    api.reset(twin, 3)
    assert not np.array_equal(obs, api.step(twin, np.zeros(api.unit)))  # the actions act


# --------------------------------------------------------------------------- seeds

BAD_SEEDS = {
    "negative": -1,
    "numpy_negative": np.int64(-3),
    "true": True,
    "false": False,
    "numpy_bool": np.bool_(True),
    "float": 3.0,
    "numpy_float": np.float64(3.0),
    "str": "3",
    "bytes": b"3",
    "complex": 3 + 0j,
    "generator": np.random.default_rng(3),
    "seed_sequence": np.random.SeedSequence(3),
    "list": [3],
    "zero_d_array": np.array(3),
}
GOOD_SEEDS = {
    "numpy_int64": np.int64(3),
    "numpy_uint8": np.uint8(3),
    "numpy_int32": np.int32(3),
}


@pytest.mark.parametrize("seed", list(BAD_SEEDS))
@api_param
def test_bad_seed_raises_naming_the_rule(api: Api, seed: str):
    env, _ = pair(api, "numpy")
    with pytest.raises(ValueError, match=SEED_RULE):
        api.reset(env, BAD_SEEDS[seed])


@pytest.mark.parametrize("seed", list(GOOD_SEEDS))
@backend_param
@api_param
def test_numpy_integer_seed_gives_the_rollout_of_the_python_int(api: Api, backend: str, seed: str):
    env, twin = pair(api, backend)
    assert np.array_equal(api.reset(env, GOOD_SEEDS[seed]), api.reset(twin, 3))
    action = np.full(api.unit, 0.5)
    for _ in range(3):
        assert np.array_equal(api.step(env, action), api.step(twin, action))
    # The generator continues alike: an unseeded reset (a seed drawn by SB3 for the VecEnv,
    # so compared with a reseeded twin there) gives the same start.
    if api.name == "vec":
        assert np.array_equal(api.reset(env, np.uint64(5)), api.reset(twin, 5))
    else:
        assert np.array_equal(api.reset(env, None), api.reset(twin, None))
    big = 2**70  # any non-negative int
    assert np.array_equal(api.reset(env, big), api.reset(twin, big))


def test_vec_env_seed_returns_python_ints():
    env, _ = pair(APIS["vec"], "numpy")
    seeds = env.seed(np.int64(4))
    assert seeds == list(range(4, 4 + B * N)) and all(type(s) is int for s in seeds)


# --------------------------------------------------------------------------- configs

LAGRANGIAN_BAD = {
    "zero": {"init_radius": 0.0},
    "below_pair_bound": {"n_agents": 2, "init_radius": 1.0, "lagrangian": {"r": 1.0}},
    "below_area_bound": {"n_agents": 20, "init_radius": 0.1},
    "no_random_start_fits": {"n_agents": 20, "init_radius": 0.2},
    "random_starts_rarely_fit": {"n_agents": 20, "init_radius": 0.5},  # < 1 in 5000 fits
    "random_starts_seldom_fit": {"n_agents": 20, "init_radius": 0.6},  # ~ 1 in 300 fits
}


@pytest.mark.parametrize("case", list(LAGRANGIAN_BAD))
@api_param
def test_lagrangian_start_radius_refused_when_the_env_is_built(api: Api, case: str):
    kwargs = {"n_agents": N, **LAGRANGIAN_BAD[case]}
    make = {
        "gym": SwarmNavEnv,
        "parallel": swarm_nav_v0.parallel_env,
        "aec": swarm_nav_v0.env,
        "vec": lambda **kw: swarm_nav_v0.vec_env(B, **kw),
    }[api.name]
    with pytest.raises(ValueError, match=r"init_radius.*lagrangian\.r"):
        make(dynamics="lagrangian", backend="numpy", **kwargs)


def test_lagrangian_bound_is_in_the_config_and_near_it_the_env_works():
    with pytest.raises(ValueError, match=r"SwarmConfig.init_radius must be in \(0, inf\)"):
        SwarmConfig(dynamics="lagrangian", lagrangian=LagrangianParams.navigation(r=0.0),
                    init_radius=0.0)  # fmt: skip
    SwarmConfig(dynamics="lagrangian", init_radius=0.0, n_agents=1)  # one agent: no pair
    SwarmConfig(dynamics="zone", init_radius=0.0)  # only the Lagrangian model has bins
    params = LagrangianParams.navigation(r=1.0)
    env = SwarmNavEnv(dynamics="lagrangian", n_agents=2, init_radius=1.5, lagrangian=params)
    for seed in range(5):  # accepted: every reset finds a start
        env.reset(seed=seed)
    env = SwarmNavEnv(dynamics="lagrangian", n_agents=20, init_radius=1.0, backend="numpy")
    for seed in range(20):  # about 1 start in 7 fits
        env.reset(seed=seed)


def test_bad_vec_env_dtype_is_a_value_error():
    with pytest.raises(ValueError, match="dtype must be float32 or float64"):
        swarm_nav_v0.vec_env(B, n_agents=N, dtype="float33")
    with pytest.raises(ValueError, match="dtype must be float32 or float64"):
        swarm_nav_v0.vec_env(B, n_agents=N, dtype=None)


# --------------------------------------------------------------------------- AEC specifics


def test_aec_done_agent_takes_only_none():
    env = swarm_nav_v0.env(n_agents=N, backend="numpy", max_cycles=1)
    env.reset(seed=0)
    for _ in range(N):
        env.step(np.zeros(D, np.float32))
    agent = env.agent_selection
    assert env.truncations[agent]
    with pytest.raises(ValueError, match=rf"action of {agent} must be None"):
        env.step(np.zeros(D, np.float32))
    env.step(None)


# --------------------------------------------------------------------------- official checkers


@backend_param
def test_official_checkers_pass_on_every_backend(backend: str):
    from gymnasium.utils.env_checker import check_env
    from pettingzoo.test import api_test, parallel_api_test
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    require(backend)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        check_env(SwarmNavEnv(n_agents=N, backend=backend), skip_render_check=True)
        sb3_check_env(SwarmNavEnv(n_agents=N, backend=backend))
        parallel_api_test(swarm_nav_v0.parallel_env(n_agents=N, backend=backend), num_cycles=20)
        api_test(swarm_nav_v0.env(n_agents=N, backend=backend), num_cycles=20)


def test_gym_make_env_follows_the_rule_through_its_wrappers():
    import gymnasium as gym

    env = gym.make("swarm_envs/SwarmNav-v0", n_agents=N, backend="numpy")
    twin = gym.make("swarm_envs/SwarmNav-v0", n_agents=N, backend="numpy")
    assert np.array_equal(env.reset(seed=np.int64(3))[0], twin.reset(seed=3)[0])
    with pytest.raises(ValueError, match=SEED_RULE):
        env.reset(seed=-3)
    env.reset(seed=3)
    with pytest.raises(ValueError, match=ACTION_RULE):
        env.step(np.zeros((N, D)))  # the (N, d) layout of the flat (N·d,) Box
    action = torch.full((N * D,), 0.5, requires_grad=True)
    assert np.array_equal(env.step(action)[0], twin.step(np.full(N * D, 0.5))[0])
