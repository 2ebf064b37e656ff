"""Strict configuration: YAML → frozen dataclasses.

Unknown keys, missing sections of the wrong type, and out-of-range values raise
:class:`ValueError` naming the key (with its dotted path) and what is allowed. VMAS
only warns on unknown keys, so typos there go unnoticed; here they stop the run. An
unknown *keyword argument* of an environment raises :class:`UnknownKeyError`, which is
both a :class:`TypeError` (what Python raises for an unexpected keyword, and what
wrappers such as TorchRL's ``GymEnv`` catch when they probe optional keywords) and a
:class:`ValueError` (so ``except ValueError`` keeps catching every config error).

>>> cfg = config_from_mapping(SwarmConfig, {"n_agents": 31, "physics": {"C_o": 0.7}})
>>> cfg.n_agents, cfg.physics.C_o
(31, 0.7)
>>> config_from_mapping(SwarmConfig, {"n_agent": 31})
Traceback (most recent call last):
...
ValueError: unknown config key 'n_agent'; allowed keys: ...
"""

from __future__ import annotations

import math
import typing
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from swarm_envs.config_mapping import (
    CONFIG_ROOT,
    as_dict,
    config_from_mapping,
    load_yaml,
    resolve_config_path,
)
from swarm_envs.models import (
    SHIPPED,
    ModelParams,
    ModelSpec,
    lagrangian_min_init_radius,
    model_names,
    model_spec,
)
from swarm_envs.perturbations import Perturbations, check_ranged
from swarm_envs.physics import (
    INTEGRATORS,
    LagrangianParams,
    PiecewiseParams,
    SocialPotentialParams,
    ZoneParams,
)
from swarm_envs.physics._validation import SUPPORTED_DIMS, check_real
from swarm_envs.tasks import task_spec, with_task_defaults

if TYPE_CHECKING:
    from swarm_envs.tasks import TaskSpec

#: The models shipped with the package (``SwarmConfig.dynamics``), the first the default,
#: from the model registry (:mod:`swarm_envs.models`, where a user's model registers too).
#: Each has its parameter section in :class:`SwarmConfig` (``physics`` for the social
#: potential, which also holds the task's goal sink ``C_g, l_g``).
DYNAMICS = SHIPPED

#: How the env computes a step (``SwarmConfig.backend``); see ``swarm_envs.envs.backends``.
BACKENDS = ("auto", "numpy", "cutoff", "native", "torch")

#: Deprecated names of backends: accepted (with a :class:`DeprecationWarning`) and
#: replaced by the name they stand for when a config is validated.
BACKEND_ALIASES = {"sparse": "cutoff"}

#: What a step that goes unstable does (``SwarmConfig.on_unstable``).
ON_UNSTABLE = ("raise", "truncate")

#: Where the goal distances are measured from (``SwarmConfig.goal_distance_scale``).
GOAL_DISTANCE_SCALES = ("absolute", "relative")

#: Volume of the unit ball by dimension (start radius from a density).
_UNIT_BALL = {2: math.pi, 3: 4.0 * math.pi / 3.0}


class UnknownKeyError(TypeError, ValueError):
    """An unknown keyword argument: a :class:`TypeError` and a :class:`ValueError`.

    Raised by :func:`check_keywords` (every environment's constructor) with Python's
    wording, ``... got an unexpected keyword argument 'name'``, followed by the known
    keywords. Unknown keys inside a YAML file or a config section remain plain
    :class:`ValueError` (``unknown config key 'physics.C_x'``): they are data, not
    keyword arguments.

    >>> issubclass(UnknownKeyError, TypeError) and issubclass(UnknownKeyError, ValueError)
    True
    """


def _check_int(owner: str, name: str, value: Any, *, low: int, high: int | None = None) -> int:
    allowed = f"[{low}, {high}]" if high is not None else f">= {low}"
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{owner}.{name} must be an integer {allowed}, got {value!r}")
    if value < low or (high is not None and value > high):
        raise ValueError(f"{owner}.{name} must be an integer {allowed}, got {value!r}")
    return int(value)


#: The default ``n_neighbors``: padding up to this many slots is quiet (see
#: :func:`_warn_empty_slots`).
DEFAULT_N_NEIGHBORS = 6
_WARNED_SLOTS: set[tuple[int, int]] = set()


def _warn_empty_slots(owner: str, n_agents: int, n_neighbors: int) -> None:
    """Warn once per ``(n_agents, n_neighbors)`` where the observation holds more
    neighbour slots than there are other agents and than the default's: those slots
    are always empty. Padding itself is accepted (one layout for every swarm size, as
    a policy trained on one ``N`` and evaluated on another needs); the default's 6
    slots with a smaller swarm say nothing."""
    if n_neighbors <= max(n_agents - 1, DEFAULT_N_NEIGHBORS):
        return
    if (n_agents, n_neighbors) in _WARNED_SLOTS:
        return
    _WARNED_SLOTS.add((n_agents, n_neighbors))
    empty = n_neighbors - max(n_agents - 1, 0)
    warnings.warn(
        f"{owner}.n_neighbors={n_neighbors} with n_agents={n_agents}: each agent has "
        f"{n_agents - 1} other{'s' if n_agents != 2 else ''}, so {empty} of its {n_neighbors} "
        f"neighbour slots {'is' if empty == 1 else 'are'} always "
        f"empty (zero, mask 0). Set n_neighbors <= {max(n_agents - 1, 0)} for a compact "
        "observation, or keep it to share one observation layout with larger swarms",
        UserWarning,
        stacklevel=4,
    )


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the reward's terms: one field per shipped term, and ``terms`` for a
    registered task's own (:mod:`swarm_envs.tasks`).

    ``r_t = Σ sign · weight · value`` over the terms of the config's task (the SwarmNav
    docstring's table lists them). In a mapping (YAML, keywords) every term is a key of
    ``reward``, its own terms' too: ``reward: {gather: 0.5}`` puts ``gather`` into
    ``terms``. A term the config's task does not have must weigh 0, and a name that is
    none of its terms is refused (:class:`SwarmConfig` checks both).

    >>> RewardWeights(progress=2.0, terms={"gather": 0.5}).terms["gather"]
    0.5
    """

    progress: float = 10.0
    """Scale of the reduction of the mean agent-to-goal distance, normalised by the start."""
    arrival: float = 1.0
    """Bonus for the fraction of agents newly inside the goal radius."""
    success: float = 5.0
    """One-off bonus when the episode succeeds."""
    collision: float = 0.5
    """Penalty per colliding pair, divided by N."""
    effort: float = 0.01
    """Penalty on the mean squared action (action units, in [0, d])."""
    time: float = 0.05
    """Penalty per step, so that arriving earlier pays."""
    mill: float = 0.0
    """Scale of the mill's order, paid every step: the members' tangential speed about
    the goal (those within the arrival radius counted) over the cruise speed ``v₀``, at
    most 1 (``info["mill_order"]``; needs self-propulsion, ``physics.alpha > 0``)."""
    terms: Mapping[str, float] = field(default_factory=dict, hash=False)
    """The weights of a registered task's own terms, by name (a copy of the mapping
    given; not to be changed in place, as the other fields cannot be)."""

    def __post_init__(self) -> None:
        owner = type(self).__name__
        for f in fields(self):
            if f.name != "terms":
                value = check_real(owner, f.name, getattr(self, f.name), low=0.0)
                object.__setattr__(self, f.name, value)
        if not isinstance(self.terms, Mapping):
            raise ValueError(f"{owner}.terms must map term names to weights, got {self.terms!r}")
        terms = {}
        for name, weight in self.terms.items():
            if name in self.shipped_terms() or name == "terms":
                raise ValueError(f"{owner}.terms: {name!r} is a field; give it as {name}=")
            terms[str(name)] = check_real(owner, f"terms.{name}", weight, low=0.0)
        object.__setattr__(self, "terms", terms)

    @classmethod
    def shipped_terms(cls) -> tuple[str, ...]:
        """The fields that weigh the shipped terms (every field but ``terms``)."""
        return tuple(f.name for f in fields(cls) if f.name != "terms")

    @classmethod
    def from_config_mapping(cls, data: Mapping[str, Any]) -> dict[str, Any]:
        """A ``reward`` section with every key not a field moved into ``terms`` (the
        config's task then checks the names)."""
        names = {f.name for f in fields(cls)}
        own = {k: v for k, v in data.items() if k not in names}
        if not own:
            return dict(data)
        given = data.get("terms", {})
        if not isinstance(given, Mapping):
            return dict(data)  # refused by the dataclass, naming the key
        out = {k: v for k, v in data.items() if k in names}
        out["terms"] = {**given, **own}
        return out

    def weight(self, name: str) -> float:
        """The weight of term ``name`` (a field, else ``terms[name]``, else 0)."""
        if name in self.shipped_terms():
            return float(getattr(self, name))
        return float(self.terms.get(name, 0.0))


@dataclass(frozen=True)
class SwarmConfig:
    """A swarm scenario: the physics, the start, and the goal-sink navigation task.

    The reproductions read the physics and start fields; the SwarmNav environments read
    all of them. Field names are also the environments' keyword arguments.
    """

    n_agents: int = 10
    """Number of agents N, ``≥ 1``. ``N = 1`` is single-agent navigation: no pairs, so no
    pair forces, collisions or neighbours (every neighbour slot is padding and the
    nearest-neighbour distance is 0)."""
    dynamics: str = "social_potential"
    """The passive physics, a model of the registry (:mod:`swarm_envs.models`): one of
    the shipped :data:`DYNAMICS`, the social potential (Mabrouk & McInnes), Couzin's zone
    model or Viscido's piecewise force model (both as in Naterop), or the Lagrangian
    gradient model (Vanualailai & Sharma), each reading its own section below, or a
    model registered by the user, reading its section of ``model_params``. How an action
    biases each is in ``swarm_envs.envs.dynamics``."""
    dim: int = 2
    """Spatial dimension d, 2 or 3."""
    dt: float = 0.1
    """Integration time step (the paper gives none; chosen and documented)."""
    integrator: str = "semi_implicit_euler"
    """One of ``swarm_envs.physics.INTEGRATORS``."""
    max_substeps: int = 1000
    """Step-size control: each step of ``dt`` is integrated in as many equal substeps as
    the state's stiffness needs for a stable step (``docs/models.md`` §7), at most this
    many; ``info["substeps"]`` reports the count. A state that needs more is unstable
    (see ``on_unstable``). 1 integrates every step in one, and still checks it."""
    on_unstable: str = "raise"
    """What a step that goes unstable does (non-finite state, or more substeps needed
    than ``max_substeps``), one of :data:`ON_UNSTABLE`: ``"raise"`` a
    :class:`~swarm_envs.envs.common.SwarmUnstableError` naming the cause and the keys to
    change, or ``"truncate"`` that swarm's episode at its last sound state with
    ``info["unstable"] = 1.0``."""
    physics: SocialPotentialParams = field(default_factory=SocialPotentialParams.navigation)
    """Social potential parameters; the goal sink ``C_g, l_g`` defines the task (the
    sink force the analytic controllers apply, for every ``dynamics``)."""
    zone: ZoneParams = field(default_factory=ZoneParams.navigation)
    """Zone model parameters (``dynamics="zone"``)."""
    piecewise: PiecewiseParams = field(default_factory=PiecewiseParams.navigation)
    """Piecewise force model parameters (``dynamics="piecewise"``)."""
    lagrangian: LagrangianParams = field(default_factory=LagrangianParams.navigation)
    """Lagrangian gradient model parameters (``dynamics="lagrangian"``); array-valued
    fields must match ``n_agents``."""
    model_params: ModelParams = field(default_factory=ModelParams)
    """The parameter sections of the registered models whose section is not one of the
    keys above, keyed by each model's section name (``ModelSpec.section``):
    ``{"cucker_smale": {"K": 2.0}}``. A section given as a mapping is built on its
    parameter class's defaults; the section of the selected ``dynamics``, where not
    given, is those defaults."""
    init_radius: float = 1.5
    """Agents start uniformly in a disc (ball) of this radius around the origin (unless
    ``init_density`` is set; see :attr:`start_radius`)."""
    init_density: float | None = None
    """Start density in agents per unit area (``d = 2``) or volume (``d = 3``), ``> 0``;
    ``None``: start in ``init_radius``. Set, the start radius is
    ``R = (N / (ω_d n))^{1/d}`` (``ω_2 = π``, ``ω_3 = 4π/3``; :attr:`start_radius`), so
    that every ``N`` starts at this density: ``R ∝ N^{1/d}``. ``init_radius`` must then
    keep its default (give one of the two); not with ``dynamics="lagrangian"``, whose
    start checks read ``init_radius``."""
    init_speed: float = 0.1
    """Initial velocities uniform in a disc (ball) of this speed."""
    goal_distance_min: float = 8.0
    """Goal placed at a random bearing, at a distance drawn uniformly from [min, max]
    (measured as ``goal_distance_scale`` says)."""
    goal_distance_max: float = 12.0
    """Upper end of the goal distance range, ``≥ goal_distance_min``."""
    goal_distance_scale: str = "absolute"
    """Where the goal distances are measured from, one of :data:`GOAL_DISTANCE_SCALES`:
    ``"absolute"`` from the origin (the centre of the start disc), ``"relative"`` from
    the edge of the start disc, so the goal lies ``start_radius + U[min, max]`` from the
    origin: ``goal_distance_min/max`` keep their meaning (how far the nearest agents
    must travel) at every ``N``."""
    goal_radius: float = 1.5
    """An agent within this distance of the goal has arrived; with
    ``goal_distance_scale="relative"`` within ``goal_radius + start_radius``, so that a
    swarm of any ``N`` fits inside (:attr:`arrival_radius`)."""
    success_fraction: float = 1.0
    """Fraction of agents that must have arrived (at once) for success, in (0, 1]."""
    max_steps: int = 400
    """Episode length before truncation."""
    u_max: float = 3.0
    """Action bound: the control force is ``u_i = u_max · a_i`` with ``a_i ∈ [−1, 1]^d``.

    The default 3 equals the largest goal-sink force ``C_g / l_g`` of the navigation set,
    so the analytic controller is never clipped."""
    goal_in_physics: bool = False
    """If true the sink also acts passively (paper eq. 21) and actions are residuals."""
    n_neighbors: int = DEFAULT_N_NEIGHBORS
    """k nearest neighbours in each agent's observation, ``≥ 0``. With fewer others
    (``N − 1 < k``) the slots past them are padding (all zero, mask 0), so that one
    observation layout fits swarms of every size; more padding than the default's
    (``k > max(N − 1, 6)``) warns once (:func:`_warn_empty_slots`)."""
    collision_radius: float = 0.1
    """Two agents closer than this collide (counted, penalised)."""
    obs_goal_scale: float = 10.0
    """The observed goal offset is divided by this length."""
    obs_neighbor_scale: float = 1.0
    """Observed neighbour offsets are divided by this length."""
    obs_velocity_scale: float = 2.0
    """Observed velocities (own and relative) are divided by this speed."""
    observe_status: bool = False
    """If true each neighbour slot of an observation ends with a flag: 1 when that
    neighbour is active, 0 when it has failed (and the central Gymnasium env appends
    every agent's flag); see ``perturbations``."""
    task: str = "navigation"
    """What the swarm must do: a registered task (:func:`~swarm_envs.tasks.task_names`),
    the package's being ``"navigation"`` (gather at the goal), ``"informed"`` (the
    same, with only ``informed_fraction`` of the agents observing the goal) and
    ``"mill"`` (reach the goal and circle it, on the self-propelled social potential).
    Each has its defaults, which the envs and :func:`load_swarm_config` apply beneath
    the given values (:mod:`swarm_envs.tasks`; a user's own task registers there)."""
    informed_fraction: float | tuple[float, float] = 1.0
    """Fraction of each swarm's agents that observe the goal (``task="informed"``, or a
    task whose spec is ``informed``), in ``(0, 1]``, or a ``[low, high]`` range drawn per
    episode; ``f·N`` agents rounded to the nearest (at least one), drawn per episode.
    Must stay 1 for the other tasks. (The
    zone model's own ``zone.informed_fraction`` is another thing: the agents its
    passive physics steers to the goal with ``goal_in_physics``.)"""
    reward: RewardWeights = field(default_factory=RewardWeights)
    """Reward weights."""
    perturbations: Perturbations = field(default_factory=Perturbations)
    """Agents that fail, join or are absent, and noise
    (:class:`~swarm_envs.perturbations.Perturbations`); none by default."""
    backend: str = "auto"
    """How a step is computed, one of :data:`BACKENDS`: ``"numpy"`` (dense, every
    model), ``"cutoff"`` (cut-off + cell list, large swarms), ``"native"`` (the step in
    C, compiled at install), ``"torch"`` (one fused, compiled step; CPU or CUDA) or
    ``"auto"``, which picks by measured speed among the backends that support the config
    (``swarm_envs.envs.backends.select_backend``). Results agree to float tolerance
    (``"cutoff"``: up to its documented cut-off error). A named backend that cannot run
    the config falls back to ``"auto"``'s pick with a warning. ``"sparse"``, a deprecated
    name of the cut-off backend, is accepted and becomes ``"cutoff"``."""
    device: str = "cpu"
    """Torch device of the ``"torch"`` backend (``"cpu"``, ``"cuda"``, ``"cuda:1"``...)."""

    def __post_init__(self) -> None:
        owner = type(self).__name__
        _check_int(owner, "n_agents", self.n_agents, low=1)
        if self.dim not in SUPPORTED_DIMS or isinstance(self.dim, bool):
            raise ValueError(f"{owner}.dim must be one of {SUPPORTED_DIMS}, got {self.dim!r}")
        if self.integrator not in INTEGRATORS:
            raise ValueError(
                f"{owner}.integrator must be one of {INTEGRATORS}, got {self.integrator!r}"
            )
        _check_int(owner, "max_substeps", self.max_substeps, low=1)
        if self.on_unstable not in ON_UNSTABLE:
            raise ValueError(
                f"{owner}.on_unstable must be one of {ON_UNSTABLE}, got {self.on_unstable!r}"
            )
        if isinstance(self.backend, str) and self.backend in BACKEND_ALIASES:
            new = BACKEND_ALIASES[self.backend]
            warnings.warn(
                f"{owner}.backend={self.backend!r} is deprecated: the backend is called {new!r}",
                DeprecationWarning,
                stacklevel=3,
            )
            object.__setattr__(self, "backend", new)
        if self.backend not in BACKENDS:
            raise ValueError(
                f"{owner}.backend must be one of {BACKENDS} (or a deprecated name: "
                f"{', '.join(map(repr, BACKEND_ALIASES))}), got {self.backend!r}"
            )
        if not isinstance(self.device, str) or not self.device:
            raise ValueError(f"{owner}.device must be a torch device name, got {self.device!r}")
        self._check_model_sections(owner)
        if not isinstance(self.reward, RewardWeights):
            raise ValueError(f"{owner}.reward must be RewardWeights")
        if not isinstance(self.goal_in_physics, bool):
            raise ValueError(f"{owner}.goal_in_physics must be true or false")
        if not isinstance(self.observe_status, bool):
            raise ValueError(f"{owner}.observe_status must be true or false")
        if not isinstance(self.perturbations, Perturbations):
            raise ValueError(f"{owner}.perturbations must be Perturbations")
        self._check_task(owner)
        allowed = model_spec(self.dynamics).integrators
        if self.integrator not in allowed:
            raise ValueError(
                f"{owner}.integrator={self.integrator!r} is not available with "
                f"dynamics={self.dynamics!r}: it takes {' or '.join(map(repr, allowed))} "
                "(the models' integrators: docs/models.md)"
            )
        if self.perturbations.needs_masks and not model_spec(self.dynamics).applies_masks:
            masks = [n for n in model_names() if model_spec(n).applies_masks]
            masked = " or ".join(f"dynamics={n!r}" for n in masks)
            raise ValueError(
                f"{owner}.perturbations: removed, frozen, absent and joining agents need "
                f"{masked} (the other models take failure_mode='passive' and the noise), "
                f"got dynamics={self.dynamics!r}"
            )
        if self.perturbations.needs_masks and self.integrator == "velocity_verlet":
            raise ValueError(
                f"{owner}.perturbations: removed, frozen, absent and joining agents need "
                f"integrator='semi_implicit_euler' or 'implicit_damping_euler', got "
                f"{self.integrator!r}"
            )
        reals: dict[str, dict[str, Any]] = {
            "dt": dict(low=0.0, low_inclusive=False),
            "init_radius": dict(low=0.0),
            "init_speed": dict(low=0.0),
            "goal_distance_min": dict(low=0.0),
            "goal_distance_max": dict(low=0.0),
            "goal_radius": dict(low=0.0, low_inclusive=False),
            "success_fraction": dict(low=0.0, high=1.0, low_inclusive=False),
            "u_max": dict(low=0.0, low_inclusive=False),
            "collision_radius": dict(low=0.0),
            "obs_goal_scale": dict(low=0.0, low_inclusive=False),
            "obs_neighbor_scale": dict(low=0.0, low_inclusive=False),
            "obs_velocity_scale": dict(low=0.0, low_inclusive=False),
        }
        for name, bounds in reals.items():
            object.__setattr__(self, name, check_real(owner, name, getattr(self, name), **bounds))
        if self.init_density is not None:
            object.__setattr__(
                self,
                "init_density",
                check_real(owner, "init_density", self.init_density, low=0.0, low_inclusive=False),
            )
            if self.init_radius != _INIT_RADIUS_DEFAULT:
                raise ValueError(
                    f"{owner}.init_density ({self.init_density!r}) and init_radius "
                    f"({self.init_radius!r}) are both set: give one (init_density sets the "
                    "start radius from N; set init_density to None to start in init_radius)"
                )
        if self.goal_distance_scale not in GOAL_DISTANCE_SCALES:
            raise ValueError(
                f"{owner}.goal_distance_scale must be one of {GOAL_DISTANCE_SCALES}, got "
                f"{self.goal_distance_scale!r}"
            )
        if self.goal_distance_max < self.goal_distance_min:
            raise ValueError(
                f"{owner}.goal_distance_max ({self.goal_distance_max}) must be >= "
                f"goal_distance_min ({self.goal_distance_min})"
            )
        _check_int(owner, "max_steps", self.max_steps, low=1)
        _check_int(owner, "n_neighbors", self.n_neighbors, low=0)
        _warn_empty_slots(owner, self.n_agents, self.n_neighbors)
        check = model_spec(self.dynamics).check
        if check is not None:
            check(self)

    def _check_model_sections(self, owner: str) -> None:
        """``dynamics`` is a registered model, the sections that are config keys hold
        their models' parameter classes, and ``model_params`` holds the other registered
        models' sections only (built from mappings; the selected model's filled with its
        defaults where absent)."""
        if not isinstance(self.dynamics, str) or self.dynamics not in model_names():
            raise ValueError(
                f"{owner}.dynamics must be one of the registered models {model_names()}, "
                f"got {self.dynamics!r}"
            )
        specs = [model_spec(name) for name in model_names()]
        for spec in filter(_section_is_key, specs):
            if not isinstance(getattr(self, spec.section), spec.params):
                raise ValueError(f"{owner}.{spec.section} must be {spec.params.__name__}")
        if not isinstance(self.model_params, Mapping):
            raise ValueError(
                f"{owner}.model_params must be a mapping of section names to parameters, "
                f"got {self.model_params!r}"
            )
        sections = {spec.section: spec for spec in specs if not _section_is_key(spec)}
        built: dict[str, Any] = {}
        for key, value in self.model_params.items():
            if key not in sections:
                keys = tuple(spec.section for spec in specs if _section_is_key(spec))
                raise ValueError(
                    f"{owner}.model_params: unknown section {key!r}; allowed: the registered "
                    f"models' sections {tuple(sections)} (the sections {keys} are keys of "
                    "the config itself)"
                )
            params = sections[key].params
            built[key] = config_from_mapping(params, value, path=f"model_params.{key}")
        spec = model_spec(self.dynamics)
        if not _section_is_key(spec) and spec.section not in built:
            built[spec.section] = spec.params()
        object.__setattr__(self, "model_params", ModelParams(built))

    def _check_task(self, owner: str) -> None:
        """The task and what it needs (:mod:`swarm_envs.tasks`): its name, the informed
        fraction, its own requirements, and reward weights for its terms only."""
        try:
            spec = task_spec(self.task)
        except ValueError as err:
            raise ValueError(f"{owner}.{err}") from None
        object.__setattr__(self, "_task_spec", spec)  # resolved once per config
        fraction = check_ranged(
            owner,
            "informed_fraction",
            self.informed_fraction,
            integer=False,
            low=0.0,
            high=1.0,
            low_inclusive=False,
        )
        object.__setattr__(self, "informed_fraction", fraction)
        if not spec.informed and fraction != 1.0:
            raise ValueError(
                f"{owner}.informed_fraction applies to task='informed' "
                f"(swarm_envs/SwarmInformed-v0) and must be 1 for task={self.task!r}, got "
                f"{fraction!r}"
            )
        self._check_reward(owner, spec)
        reason = spec.check(self) if spec.check is not None else None
        if reason is not None:
            raise ValueError(f"{owner}.task={self.task!r} {reason}")

    def _check_reward(self, owner: str, spec: TaskSpec) -> None:
        """Weights for the task's terms only: an unknown name, or a weight on a shipped
        term the task does not have, is refused naming the task's terms."""
        terms = spec.term_names
        listed = f"task {self.task!r} has the reward terms {', '.join(terms)}"
        for name in self.reward.terms:
            if name not in terms:
                raise ValueError(f"unknown config key 'reward.{name}'; {listed}")
        for name in RewardWeights.shipped_terms():
            if name not in terms and getattr(self.reward, name) != 0:
                raise ValueError(
                    f"{owner}.reward.{name} = {getattr(self.reward, name)!r} weighs no term: "
                    f"{listed} (its config defaults, tasks.task_config({self.task!r}), weigh "
                    "those only)"
                )
        if self.reward.mill > 0 and self.physics.alpha <= 0:
            raise ValueError(
                f"{owner}.reward.mill rewards circling at the cruise speed of "
                f"self-propulsion: it needs physics.alpha > 0, got {self.physics.alpha!r}"
            )

    @property
    def task_spec(self) -> TaskSpec:
        """The registered :class:`~swarm_envs.tasks.TaskSpec` of ``task``, as it was
        when this config was built (looked up once)."""
        return self.__dict__["_task_spec"]

    def __getstate__(self) -> dict[str, Any]:
        """The fields (a task's spec holds functions: it is looked up again on loading)."""
        state = dict(self.__dict__)
        state.pop("_task_spec", None)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        object.__setattr__(self, "_task_spec", task_spec(self.task))

    @property
    def dynamics_params(self) -> Any:
        """The parameters of the selected model: its section of the config (the keys
        ``physics``, ``zone``, ``piecewise``, ``lagrangian``, or ``model_params[section]``
        for the other registered models).

        >>> SwarmConfig(dynamics="zone").dynamics_params == SwarmConfig().zone
        True
        """
        spec = model_spec(self.dynamics)
        if _section_is_key(spec):
            return getattr(self, spec.section)
        return self.model_params[spec.section]

    @property
    def passive_sink(self) -> bool:
        """Whether the goal pulls every agent in the physics: the social potential's sink
        (``goal_in_physics`` and ``physics.C_g > 0``)."""
        return self.goal_in_physics and self.physics.C_g > 0

    @property
    def needs_statuses(self) -> bool:
        """Whether the core takes agent statuses (``set_status`` is called): agents that
        leave or stop in the physics, or observations with status flags."""
        return self.perturbations.needs_masks or self.observe_status

    @property
    def informs_agents(self) -> bool:
        """Whether only some agents observe the goal, drawn per episode, and the
        observation says who (``task="informed"``; the task spec's ``informed``)."""
        return self.task_spec.informed

    @property
    def start_radius(self) -> float:
        """The radius of the start disc (ball): ``init_radius``, or with ``init_density``
        set, ``(N / (ω_d · init_density))^{1/d}``.

        >>> SwarmConfig().start_radius
        1.5
        >>> cfg = SwarmConfig(n_agents=100_000, init_density=10 / (math.pi * 1.5**2))
        >>> round(cfg.start_radius, 6)  # 10 agents in a disc of 1.5, scaled to 100,000
        150.0
        """
        if self.init_density is None:
            return self.init_radius
        return (self.n_agents / (_UNIT_BALL[self.dim] * self.init_density)) ** (1.0 / self.dim)

    @property
    def arrival_radius(self) -> float:
        """The distance from the goal within which an agent has arrived: ``goal_radius``,
        or with ``goal_distance_scale="relative"``, ``goal_radius + start_radius`` (the
        goal region grows with the swarm as the goal distance does).

        >>> SwarmConfig().arrival_radius
        1.5
        >>> cfg = SwarmConfig(n_agents=1000, init_density=0.3, goal_distance_scale="relative")
        >>> round(cfg.arrival_radius - cfg.start_radius, 6)
        1.5
        """
        if self.goal_distance_scale == "relative":
            return self.goal_radius + self.start_radius
        return self.goal_radius


#: ``SwarmConfig.init_radius``'s default (``init_density`` requires it unchanged).
_INIT_RADIUS_DEFAULT = next(f.default for f in fields(SwarmConfig) if f.name == "init_radius")

#: The type of each :class:`SwarmConfig` field.
_FIELD_TYPES = typing.get_type_hints(SwarmConfig)


def _section_is_key(spec: ModelSpec) -> bool:
    """Whether a model's section is a key of the config itself (a field of its parameter
    class: the four models shipped first), not an entry of ``model_params``."""
    return _FIELD_TYPES.get(spec.section) is spec.params


def check_keywords(given: Iterable[str], owner: str, keywords: Sequence[str] = ("config",)) -> None:
    """Refuse a keyword that is neither one of ``keywords`` nor a :class:`SwarmConfig` field.

    ``owner`` names the callable in the message; ``keywords`` are its own keyword
    arguments besides the config fields.

    >>> check_keywords(["n_agents", "config"], "SwarmNavEnv()")
    >>> try:
    ...     check_keywords(["frameskip"], "SwarmNavEnv()")
    ... except TypeError as err:
    ...     print(str(err)[:69])
    SwarmNavEnv() got an unexpected keyword argument 'frameskip'; allowed
    """
    names = {f.name for f in fields(SwarmConfig)}
    for key in given:
        if key not in names and key not in keywords:
            raise UnknownKeyError(
                f"{owner} got an unexpected keyword argument {key!r}; allowed keys: "
                f"{', '.join(keywords)}, and the config keys {', '.join(sorted(names))}"
            )


def load_swarm_config(
    path: str | Path | None = None, overrides: Mapping[str, Any] | None = None
) -> SwarmConfig:
    """Load a :class:`SwarmConfig` from YAML, then apply keyword ``overrides`` strictly.

    Overrides replace top-level keys; a nested section given as a mapping is merged
    into the file's section (``physics={"C_o": 0.7}`` changes only ``C_o``). Both lie
    over the defaults of the resulting ``task`` (:mod:`swarm_envs.tasks`).
    """
    data: dict[str, Any] = load_yaml(resolve_config_path(path)) if path is not None else {}
    for key, value in (overrides or {}).items():
        if isinstance(value, Mapping) and isinstance(data.get(key), Mapping):
            merged = {**data[key], **value}
            if key == "model_params":  # sections of sections: merged one level deeper
                for name, section in value.items():
                    old = data[key].get(name)
                    if isinstance(section, Mapping) and isinstance(old, Mapping):
                        merged[name] = {**old, **section}
            data[key] = merged
        else:
            data[key] = value
    return config_from_mapping(SwarmConfig, with_task_defaults(data))


__all__ = [
    "BACKENDS",
    "BACKEND_ALIASES",
    "CONFIG_ROOT",
    "DYNAMICS",
    "GOAL_DISTANCE_SCALES",
    "ON_UNSTABLE",
    "RewardWeights",
    "SwarmConfig",
    "UnknownKeyError",
    "as_dict",
    "check_keywords",
    "config_from_mapping",
    "lagrangian_min_init_radius",
    "load_swarm_config",
    "load_yaml",
    "resolve_config_path",
]
