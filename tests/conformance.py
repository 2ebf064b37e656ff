"""The conformance suite's machinery: every backend against the reference, config by config.

A *variant* is a backend and a state dtype (plus, for the C step, its build flags). For a
config, :func:`check` runs the same seeded rollout, with random actions and the VecEnv's
automatic resets of ended swarms, on the variant and on the reference (the numpy core in
float64), and returns the mismatches it finds, each naming the quantity (an observation
feature, a statistic, the reward, a flag). A variant that cannot run the config must
refuse it up front with a reason (``unsupported``); :func:`check` then returns that
reason instead. A config with perturbations runs both cores inside
:class:`~swarm_envs.envs.perturbed.PerturbedCore`, which draws the failures, joins and
noise from the reset's generator: the same seed gives both the same perturbations.

Comparisons stop at the first step whose outcome the reference cannot decide to the
variant's precision: a pair at the collision radius, an agent at the goal radius, two
neighbours at (almost) the same distance. There the rounding of an exact computation may
legitimately go either way; everything before it must agree.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
from collections.abc import Iterator
from typing import Any

import numpy as np
from hypothesis import strategies as st

from swarm_envs.config import DYNAMICS, INTEGRATORS, SwarmConfig, config_from_mapping
from swarm_envs.envs import backends
from swarm_envs.envs.cores.numpy import SwarmNavCore
from swarm_envs.envs.perturbed import PerturbedCore
from swarm_envs.envs.task import ranked_neighbors, stat_keys
from swarm_envs.envs.task.agent_status import ABSENT, ACTIVE, FAILED, FROZEN, masks
from swarm_envs.envs.task.observation import observation_size
from swarm_envs.models import model_spec
from swarm_envs.perturbations import FAILURE_MODES, Perturbations
from swarm_envs.tasks import TASKS, task_spec

#: Tolerances against the float64 reference, per state dtype (float64: round-off).
TOLERANCE = {
    np.dtype(np.float64): dict(rtol=1e-9, atol=1e-9),
    np.dtype(np.float32): dict(rtol=2e-3, atol=2e-3),
}
#: How close to a threshold the reference may be before a step is undecidable.
MARGIN = {np.dtype(np.float64): 1e-9, np.dtype(np.float32): 2e-4}

BATCH = 3
STEPS = 14


@dataclasses.dataclass(frozen=True)
class Variant:
    """A backend, a dtype and, for the C step, the ``-march`` target of its build."""

    backend: str
    dtype: Any
    arch: str | None = None

    @property
    def name(self) -> str:
        arch = f"-{self.arch}" if self.arch else ""
        return f"{self.backend}{arch}-{np.dtype(self.dtype).name}"

    @contextlib.contextmanager
    def environment(self) -> Iterator[None]:
        """The C step's build flags for this variant (its own cached library)."""
        if self.arch is None:
            yield
            return
        old = os.environ.get("SWARM_ENVS_NATIVE_ARCH")
        os.environ["SWARM_ENVS_NATIVE_ARCH"] = self.arch
        try:
            yield
        finally:
            if old is None:
                del os.environ["SWARM_ENVS_NATIVE_ARCH"]
            else:
                os.environ["SWARM_ENVS_NATIVE_ARCH"] = old

    def unsupported(self, cfg: SwarmConfig) -> str | None:
        with self.environment():
            return backends.unsupported(cfg, self.backend)

    def make(self, cfg: SwarmConfig) -> Any:
        """This variant's core for ``cfg``, inside :class:`PerturbedCore` where ``cfg``
        perturbs (as ``make_core`` builds it)."""
        with self.environment():
            cls = backends._core_class(self.backend)
            if self.backend == "torch":
                core = cls(cfg, batch=BATCH, dtype=self.dtype, compile=False)
            elif self.backend == "cutoff":  # a cut-off past every pair: exact up to round-off
                core = cls(cfg, batch=BATCH, dtype=self.dtype, cutoff_tol=1e-300)
            else:
                core = cls(cfg, batch=BATCH, dtype=self.dtype)
            return perturbed(core)


def perturbed(core: Any) -> Any:
    """``core`` with its config's perturbations (:class:`PerturbedCore`), as
    ``make_core`` wraps it; ``core`` itself where nothing is perturbed."""
    return PerturbedCore(core) if core.cfg.perturbations.any else core


def reference(cfg: SwarmConfig) -> Any:
    """The reference for ``cfg``: the numpy core in float64 (with its perturbations)."""
    return perturbed(SwarmNavCore(cfg, batch=BATCH, dtype=np.float64))


VARIANTS = (
    Variant("numpy", np.float32),
    Variant("cutoff", np.float64),
    Variant("torch", np.float64),
    Variant("torch", np.float32),
    Variant("native", np.float64),
    Variant("native", np.float32),
    Variant("native", np.float64, arch="x86-64-v3"),
    Variant("native", np.float32, arch="x86-64-v3"),
)


# --------------------------------------------------------------------------- configs


def _real(low: float, high: float) -> st.SearchStrategy[float]:
    return st.floats(low, high, allow_nan=False, allow_infinity=False)


def _ranged(values: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
    """A value, or a range ``(low, high)`` of two (a value drawn per episode)."""
    return st.one_of(values, st.tuples(values, values).map(lambda r: tuple(sorted(r))))


def perturbation_strategies() -> dict[str, Any]:
    """A strategy per :class:`~swarm_envs.perturbations.Perturbations` field.

    Each of the three agent fractions stays at or below 0.3 (together below 1, as the
    config requires); the failure and join steps fall inside the drawn episodes
    (``max_steps`` up to 10) and the suite's rollouts.
    """
    fraction = st.one_of(st.just(0.0), _real(0.0, 0.3))
    noise = st.one_of(st.just(0.0), _real(0.0, 0.5))
    return {
        "failed_fraction": _ranged(fraction),
        "failure_mode": st.sampled_from(FAILURE_MODES),
        "failure_time": _ranged(st.integers(0, 12)),
        "absent_fraction": _ranged(fraction),
        "join_fraction": _ranged(fraction),
        "join_time": _ranged(st.integers(1, 12)),
        "obs_noise": _ranged(noise),
        "action_noise": _ranged(noise),
        "neighbor_dropout": _ranged(st.one_of(st.just(0.0), _real(0.0, 0.9))),
    }


def field_strategies(
    dynamics: tuple[str, ...] = ("social_potential",), tasks: tuple[str, ...] = TASKS
) -> dict[str, Any]:
    """A strategy per drawn :class:`SwarmConfig` field (a dict of strategies for a section).

    ``tasks``: the registered tasks drawn (the package's by default; a user's own task
    is checked by naming it, its own reward terms' weights drawn by :func:`configs`).

    The physics stays in ranges where a few dozen steps of the explicit integration stay
    finite and smooth (stiff settings are for the step-size control, not for a
    comparison of backends).
    """
    weight = st.one_of(st.just(0.0), _real(0.0, 20.0))
    return {
        "n_agents": st.integers(1, 40),
        "dim": st.sampled_from((2, 3)),
        "dt": _real(0.005, 0.1),
        "integrator": st.sampled_from(INTEGRATORS),
        # a low cap makes swarms go over it: their steps are undone and truncated alike
        # (raising is checked by each backend's own tests, where it is one exception)
        "max_substeps": st.integers(1, 64),
        "on_unstable": st.just("truncate"),
        "dynamics": st.sampled_from(dynamics),
        "init_radius": _real(0.3, 4.0),
        "init_density": st.one_of(st.none(), _real(0.2, 3.0)),
        "goal_distance_scale": st.sampled_from(("absolute", "relative")),
        "init_speed": _real(0.0, 1.0),
        "goal_distance_min": _real(0.0, 6.0),
        "goal_distance_max": _real(0.0, 6.0),  # added to the minimum
        "goal_radius": _real(0.05, 5.0),
        "success_fraction": _real(0.05, 1.0),
        "max_steps": st.integers(1, 10),
        "u_max": _real(0.1, 5.0),
        "goal_in_physics": st.booleans(),
        "n_neighbors": st.integers(0, 9),
        "collision_radius": _real(0.0, 1.0),
        "obs_goal_scale": _real(0.5, 20.0),
        "obs_neighbor_scale": _real(0.2, 5.0),
        "obs_velocity_scale": _real(0.2, 5.0),
        "observe_status": st.booleans(),
        "perturbations": perturbation_strategies(),
        "task": st.sampled_from(tasks),
        "informed_fraction": _ranged(_real(0.05, 1.0)),
        "reward": {
            name: weight
            for name in ("progress", "arrival", "success", "collision", "effort", "time", "mill")
        },
        "physics": {
            "C_a": _real(0.0, 2.0),
            "C_r": _real(0.0, 2.0),
            "l_a": _real(0.5, 2.0),
            "l_r": _real(0.2, 1.0),
            "C_o": st.one_of(st.just(0.0), _real(0.0, 1.0)),
            "l_o": _real(0.5, 2.0),
            "beta": _real(0.0, 2.0),
            "C_g": st.one_of(st.just(0.0), _real(0.0, 15.0)),
            "l_g": _real(1.0, 10.0),
            "m": _real(0.5, 2.0),
            "alpha": st.one_of(st.just(0.0), _real(0.0, 1.0)),
        },
    }


#: The fields drawn only for the perturbed share of the configs (about one in
#: :data:`PERTURBED_ONE_IN`); the others keep their defaults (nothing perturbed).
PERTURBED_FIELDS = ("observe_status", "perturbations")
PERTURBED_ONE_IN = 3

#: The perturbations that take agents out of the physics or stop them (the config
#: allows them with the social potential and semi-implicit Euler only).
_MASK_DEFAULTS = {"failure_mode": "passive", "absent_fraction": 0.0, "join_fraction": 0.0}


@st.composite
def configs(
    draw: Any, dynamics: tuple[str, ...] = ("social_potential",), tasks: tuple[str, ...] = TASKS
) -> SwarmConfig:
    """A random valid config: every field of :func:`field_strategies` drawn.

    For a task of ``tasks`` without some shipped reward term that term weighs 0, and its
    own terms' weights are drawn too.

    Roughly one config in :data:`PERTURBED_ONE_IN` is perturbed (``observe_status`` and
    the ``perturbations`` section drawn); the others perturb nothing, so the draws share
    the examples with the rest of the config rather than adding a pass of their own.
    """
    perturb = draw(st.integers(0, PERTURBED_ONE_IN - 1)) == PERTURBED_ONE_IN - 1
    fields: dict[str, Any] = {}
    for name, strategy in field_strategies(dynamics, tasks).items():
        if name in PERTURBED_FIELDS and not perturb:
            continue
        if isinstance(strategy, dict):
            fields[name] = {key: draw(s) for key, s in strategy.items()}
        else:
            fields[name] = draw(strategy)
    fields["goal_distance_max"] += fields["goal_distance_min"]
    physics = fields["physics"]
    if fields["task"] == "mill" and fields["dynamics"] != "social_potential":
        fields["task"] = "navigation"  # the mill is a task of the social potential
    if fields["task"] == "mill" and physics["alpha"] == 0:
        physics["alpha"] = 0.5  # and of its self-propelled form
    spec = task_spec(fields["task"])
    if not spec.informed:
        fields["informed_fraction"] = 1.0  # the fraction of the informed task only
    for name in fields["reward"]:
        if name not in spec.term_names:
            fields["reward"][name] = 0.0  # a term this task does not have
    weight = field_strategies()["reward"]["progress"]
    for name in spec.term_names:
        if name not in fields["reward"]:
            fields["reward"][name] = draw(weight)  # the task's own term
    if physics["alpha"] == 0:
        fields["reward"]["mill"] = 0.0  # the mill's order needs a cruise speed
    if physics["alpha"] > 0:  # self-propulsion needs a Rayleigh coefficient
        physics["beta"] = max(physics["beta"], 0.25)
    if fields["dynamics"] == "lagrangian":
        fields["init_density"] = None  # its start checks read init_radius
        fields["lagrangian"] = {"r": 0.01}  # bins small enough for any start radius
        fields["init_radius"] = max(fields["init_radius"], 0.1 * fields["n_agents"])
    if fields["init_density"] is not None:
        fields.pop("init_radius")  # one of the two sets the start radius
    if fields["integrator"] not in model_spec(fields["dynamics"]).integrators:
        fields["integrator"] = "semi_implicit_euler"  # the model's own update
    physical = fields["dynamics"] == "social_potential"
    if perturb and not (physical and fields["integrator"] != "velocity_verlet"):
        fields["perturbations"].update(_MASK_DEFAULTS)  # passive failures and noise only
    return config_from_mapping(SwarmConfig, fields)


#: The fields the strategy does not draw, and why.
NOT_DRAWN = {
    "backend": "the suite runs each backend itself",
    "device": "CUDA is covered by the GPU tests",
    **{
        model_spec(name).section: "other models' sections: drawn with their defaults "
        f"({', '.join(model_spec(name).backends)} only)"
        for name in DYNAMICS
        if model_spec(name).section not in field_strategies(DYNAMICS)
        and model_spec(name).section in {f.name for f in dataclasses.fields(SwarmConfig)}
    },
    "model_params": "the other registered models' sections: their own tests "
    "(tests/test_user_model.py)",
}

#: Every shipped dynamics (the model registry's), for the refusal checks.
ALL_DYNAMICS = DYNAMICS


# --------------------------------------------------------------------------- rollouts


def rollout(core: Any, seed: int, steps: int = STEPS) -> list[tuple]:
    """``(obs, reward, terminated, truncated, stats)`` per step of a seeded rollout with
    random actions, the ended swarms reset after each step as the VecEnv resets them
    (their observations after the reset as a further entry)."""
    rng = np.random.default_rng(seed)
    core.reset(rng)
    out = [(core.observe(), None, None, None, core.stats())]
    shape = (core.batch, core.cfg.n_agents, core.cfg.dim)
    actions = np.random.default_rng(seed + 1)
    for _ in range(steps):
        a = actions.uniform(-1.2, 1.2, shape)
        reward, terminated, truncated, stats = core.step(a.astype(core.dtype))
        out.append((core.observe(), reward, terminated, truncated, stats))
        ended = terminated | truncated
        if ended.any():
            core.reset(rng, which=ended)
            out.append((core.observe(), None, None, None, core.stats()))
    return out


def _undecidable(core: Any, margin: float) -> str | None:
    """What makes the reference's current state undecidable at ``margin``, if anything.

    With agent statuses, only what the definitions read counts: the members (mobile
    agents) for the centroid and the goal radius, and the pairs of present agents for
    the collision radius and the neighbour ranking."""
    cfg, x, goal = core.cfg, core.x, core.goal
    n = cfg.n_agents
    status = getattr(core, "status", None)
    if status is None:
        members = present = np.ones(x.shape[:-1], dtype=bool)
    else:
        _, members, present = masks(status)
    scale = max(1.0, float(np.abs(x).max()))
    tol = margin * scale
    speed = np.linalg.norm(core.v, axis=-1)
    if ((speed > 0) & (speed < 1e-30) & members).any():
        return "a speed below float32's range (no heading in float32)"
    weight = members[..., None].astype(np.float64)
    centre = (x * weight).sum(axis=-2, keepdims=True) / np.maximum(weight.sum(-2, keepdims=True), 1)
    radius = np.linalg.norm(x - centre, axis=-1)
    near_centre = (radius > 0) & (radius < 1e3 * np.finfo(np.float32).eps * scale) & members
    if n > 1 and near_centre.any():
        return "an agent at the centroid to float32's precision (no radial direction)"
    gd = np.linalg.norm(goal[:, None, :] - x, axis=-1)
    if ((np.abs(gd - cfg.arrival_radius) < tol) & members).any():
        return "an agent at the goal radius"
    if n > 1:
        rho = np.linalg.norm(x[:, :, None] - x[:, None, :], axis=-1)
        rho[~(present[:, :, None] & present[:, None, :])] = np.inf
        rho[:, np.arange(n), np.arange(n)] = np.inf
        if (np.abs(rho - cfg.collision_radius) < tol).any():
            return "a pair at the collision radius"
        k = min(ranked_neighbors(cfg) + 1, n - 1)
        ranked = np.sort(rho, axis=-1)[..., :k]
        with np.errstate(invalid="ignore"):  # inf - inf: absent agents, ranked last
            if (np.diff(ranked, axis=-1) < tol).any():
                return "two neighbours at the same distance"
    return None


def check(variant: Variant, cfg: SwarmConfig, seed: int = 0) -> list[str]:
    """Mismatches of ``variant`` against the reference on ``cfg`` (empty: it conforms).

    A variant that refuses ``cfg`` returns ``["refused: <reason>"]``; a refusal without
    a reason, or a core that raises after not refusing, is itself a mismatch.
    """
    reason = variant.unsupported(cfg)
    if reason is not None:
        return [f"refused: {reason}"] if reason.strip() else ["refused without a reason"]
    dtype = np.dtype(variant.dtype)
    tol, margin = TOLERANCE[dtype], MARGIN[dtype]
    ref_core = reference(cfg)
    ours_core = variant.make(cfg)
    return compare(ours_core, ref_core, seed, tol, margin)


def compare(ours_core: Any, ref_core: Any, seed: int, tol: dict, margin: float) -> list[str]:
    """Step both cores in lockstep and name what differs (see :func:`check`).

    Both draw their starts, perturbations and noise from generators of the same seed,
    so with the same actions they see the same failures, joins, noise and dropout."""
    cfg = ref_core.cfg
    rng, ref_rng = np.random.default_rng(seed), np.random.default_rng(seed)
    ours_core.reset(rng)
    ref_core.reset(ref_rng)
    actions = np.random.default_rng(seed + 1)
    shape = (BATCH, cfg.n_agents, cfg.dim)
    problems: list[str] = []
    for step in range(STEPS + 1):
        if _undecidable(ref_core, margin) is not None:
            break
        obs, ref_obs = ours_core.observe(), ref_core.observe()
        problems += _obs_mismatch(obs, ref_obs, cfg, tol, step)
        problems += _stats_mismatch(ours_core.stats(), ref_core.stats(), tol, step, cfg)
        if problems or step == STEPS:
            break
        a = actions.uniform(-1.2, 1.2, shape)
        ours = ours_core.step(a.astype(ours_core.dtype))
        ref = ref_core.step(a)
        if ours[0].dtype != np.float64 or ours[0].shape != (BATCH,):
            problems.append(f"step {step}: reward dtype/shape {ours[0].dtype} {ours[0].shape}")
        if _undecidable(ref_core, margin) is not None:
            break
        problems += _step_mismatch(ours, ref, tol, step, cfg)
        if problems:
            break
        ended = ref[1] | ref[2]
        if ended.any():
            ours_core.reset(rng, which=ended)
            ref_core.reset(ref_rng, which=ended)
    return problems


def observation_features(cfg: SwarmConfig) -> list[str]:
    """The name of every observation column (the shared layout; a task's features by
    name, with ``.c`` for the c-th entry of a wider one)."""
    d, k = cfg.dim, cfg.n_neighbors
    axes = "xyz"[:d]
    names = [f"goal_offset.{a}" for a in axes] + [f"velocity.{a}" for a in axes]
    features = cfg.task_spec.features

    def columns(f: Any) -> list[str]:
        width = f.size(cfg)
        return [f.name] if width == 1 else [f"{f.name}.{c}" for c in range(width)]

    for f in features:
        names += columns(f)
    for s in range(k):
        names += [f"neighbor{s}.offset.{a}" for a in axes]
        names += [f"neighbor{s}.relative_velocity.{a}" for a in axes]
        names.append(f"neighbor{s}.mask")
        if cfg.observe_status:
            names.append(f"neighbor{s}.status")
        for f in features:
            if f.neighbors:
                names += [f"neighbor{s}.{c}" for c in columns(f)]
    assert len(names) == observation_size(cfg)
    return names


def _obs_mismatch(obs: np.ndarray, ref: np.ndarray, cfg: SwarmConfig, tol: dict, step: int):
    if obs.dtype != np.float32 or obs.shape != ref.shape:
        return [f"step {step}: observation {obs.dtype} {obs.shape}, expected float32 {ref.shape}"]
    bad = ~np.isclose(obs, ref, **tol).all(axis=(0, 1))
    names = observation_features(cfg)
    return [f"step {step}: observation {names[i]}" for i in np.flatnonzero(bad)]


def _step_mismatch(ours: tuple, ref: tuple, tol: dict, step: int, cfg: Any) -> list[str]:
    """Where one step's ``(reward, terminated, truncated, stats)`` differ from the
    reference's."""
    problems = []
    if not np.allclose(ours[0], ref[0], **tol):
        problems.append(f"step {step}: reward {ours[0]} != {ref[0]}")
    for name, i in (("terminated", 1), ("truncated", 2)):
        if not np.array_equal(ours[i], ref[i]):
            problems.append(f"step {step}: {name} {ours[i]} != {ref[i]}")
    return problems + _stats_mismatch(ours[3], ref[3], tol, step, cfg)


def _stats_mismatch(stats: dict, ref: dict, tol: dict, step: int, cfg: Any) -> list[str]:
    keys = stat_keys(cfg)  # STAT_KEYS, then the task's own statistics
    if list(stats) != list(keys) or list(ref) != list(keys):
        return [f"step {step}: statistics {list(stats)}"]
    out = []
    for key in keys:
        scale = max(1.0, float(np.abs(ref[key]).max()))
        if stats[key].dtype != ref[key].dtype and key in (
            "fraction_arrived",
            "collisions",
            "success",
        ):
            out.append(f"step {step}: statistic {key} dtype {stats[key].dtype}")
        elif not np.allclose(stats[key], ref[key], rtol=tol["rtol"], atol=tol["atol"] * scale):
            out.append(f"step {step}: statistic {key} {stats[key]} != {ref[key]}")
    return out


# --------------------------------------------------------------------------- statuses

#: The config of the status-sequence property: agents leave and join the physics and
#: the observation shows their statuses (the core takes any status sequence).
STATUS_CONFIG = SwarmConfig(
    n_agents=10,
    n_neighbors=4,
    max_steps=9,
    observe_status=True,
    on_unstable="truncate",
    perturbations=Perturbations(absent_fraction=0.1, join_fraction=0.1, failure_mode="removed"),
)
STATUS_STEPS = 16


@dataclasses.dataclass(frozen=True)
class StatusEvent:
    """After step ``step``, agent ``agent`` of swarm ``swarm`` takes ``status``: it
    joins (from ``ABSENT``, placed at its start, at rest), fails (``FAILED``,
    ``FROZEN``), leaves (``ABSENT``) or comes back to ``ACTIVE``."""

    step: int
    swarm: int
    agent: int
    status: int


@st.composite
def status_sequences(draw: Any, batch: int = BATCH, cfg: SwarmConfig = STATUS_CONFIG) -> tuple:
    """``(start statuses (B, N) int8, events)``: each agent's status at the start, then
    status changes at random steps. Agent 0 of every swarm stays active (a config always
    leaves some agent that never fails), so that a swarm always has members."""
    n = cfg.n_agents
    status = st.sampled_from((ACTIVE, FAILED, FROZEN, ABSENT))
    start = np.array(
        draw(st.lists(st.lists(status, min_size=n, max_size=n), min_size=batch, max_size=batch)),
        dtype=np.int8,
    )
    start[:, 0] = ACTIVE
    events = draw(
        st.lists(
            st.builds(
                StatusEvent,
                st.integers(0, STATUS_STEPS - 1),
                st.integers(0, batch - 1),
                st.integers(1, n - 1),
                status,
            ),
            max_size=4 * STATUS_STEPS,
        )
    )
    return start, sorted(events, key=lambda e: e.step)


def compare_statuses(
    ours_core: Any,
    ref_core: Any,
    start: np.ndarray,
    events: list,
    seed: int,
    tol: dict,
    margin: float,
) -> list[str]:
    """Step both cores (without :class:`PerturbedCore`: the statuses are given) through
    the same status sequence, with the same random actions, and name what differs.

    The statuses at the start apply after every reset (an ended swarm starts again with
    them); an event changes a swarm's statuses after its step, placing joining agents at
    their episode's start position (as perturbations place them). Agents that do not act
    get zero actions, as :func:`~swarm_envs.envs.task.agent_status.perturb_actions`
    gives them. Stops at the first step the reference cannot decide (:func:`compare`)."""
    cfg = ref_core.cfg
    rng, ref_rng = np.random.default_rng(seed), np.random.default_rng(seed)
    ours_core.reset(rng)
    ref_core.reset(ref_rng)
    B = ref_core.batch
    every = np.ones(B, dtype=bool)
    status = start.copy()
    starts = ref_core.x.copy()
    for core in (ours_core, ref_core):
        core.set_status(status, rows=every, start=True)
    actions = np.random.default_rng(seed + 1)
    shape = (B, cfg.n_agents, cfg.dim)
    problems: list[str] = []
    queue = list(events)
    for step in range(STATUS_STEPS + 1):
        if _undecidable(ref_core, margin) is not None:
            break
        problems += _obs_mismatch(ours_core.observe(), ref_core.observe(), cfg, tol, step)
        problems += _stats_mismatch(ours_core.stats(), ref_core.stats(), tol, step, cfg)
        if problems or step == STATUS_STEPS:
            break
        a = actions.uniform(-1.2, 1.2, shape) * (status == ACTIVE)[..., None]
        ours = ours_core.step(a.astype(ours_core.dtype))
        ref = ref_core.step(a)
        if _undecidable(ref_core, margin) is not None:
            break
        problems += _step_mismatch(ours, ref, tol, step, cfg)
        if problems:
            break
        ended = ref[1] | ref[2]
        if ended.any():
            ours_core.reset(rng, which=ended)
            ref_core.reset(ref_rng, which=ended)
            status[ended] = start[ended]
            starts[ended] = ref_core.x[ended]
            for core in (ours_core, ref_core):
                core.set_status(status, rows=ended, start=True)
        new = status.copy()
        while queue and queue[0].step == step:
            e = queue.pop(0)
            if not ended[e.swarm]:
                new[e.swarm, e.agent] = e.status
        if (new != status).any():
            place = (status == ABSENT) & (new != ABSENT)
            for core in (ours_core, ref_core):
                at = starts.astype(core.dtype)
                core.set_status(new, place if place.any() else None, at)
            status = new
    return problems
