"""The registry of physics models: one :class:`ModelSpec` per ``SwarmConfig.dynamics``.

A model is a passive physics and the way an action biases it. Its entry holds everything
the rest of the package needs to know about it, and the rest of the package reads the
entry instead of listing models:

==============================  =======================================================
who reads it                    what from the entry
==============================  =======================================================
``swarm_envs.config``           the names ``dynamics`` accepts; the parameter class of
                                each config section; what the model requires of the
                                rest of the config (:attr:`ModelSpec.check`)
``physics.simulate``            the simulator of a parameter type
``envs.dynamics.make_dynamics``  the environment's adapter (a ``Dynamics`` subclass)
``envs.step_control``           the step-size rule (the substeps a step needs)
``envs.backends`` and the C     which cores implement the model; the others refuse it up
contract                        front, and the env falls back to one that does
``agents``                      the analytic baseline controller, by name
``tests/conformance.py``        the shipped models and their sections
==============================  =======================================================

Layering. This module sits beside the config, above the physics, and imports nothing but
the physics: the config reads it, and ``physics.simulate`` looks a parameter type up in it
when it is called. An entry names what lives above it without importing it: the adapter
and the step-size rule as objects or by their import path ``"module:attr"`` (resolved on
first use, like a Gymnasium ``entry_point``), the baseline controller by its name in
``agents.CONTROLLERS``. The shipped models name theirs by path, so that importing the
config imports no environment code; a user's model, written above every layer, passes the
objects themselves.

A model of one's own is a parameter class, a simulator, an adapter and one call of
:func:`register_model`, in one file (``docs/design.md``, "Adding a model";
``examples/cucker_smale_model.py``). Its parameters are the config's
``model_params[<section>]``; the four shipped models keep their own config sections
(``physics``, ``zone``, ``piecewise``, ``lagrangian``).

>>> model_spec("zone").params.__name__, model_spec("zone").section
('ZoneParams', 'zone')
>>> try:
...     model_spec("boids")
... except ValueError as err:
...     print(err)  # doctest: +ELLIPSIS
dynamics must be one of the registered models ('social_potential', 'zone', 'piecewise', \
'lagrangian'...), got 'boids'
"""

from __future__ import annotations

import dataclasses
import importlib
import textwrap
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from swarm_envs.physics.integrators import INTEGRATORS, simulate
from swarm_envs.physics.lagrangian import LagrangianParams, simulate_lagrangian
from swarm_envs.physics.piecewise import PiecewiseParams, simulate_piecewise
from swarm_envs.physics.social_potential import SocialPotentialParams
from swarm_envs.physics.zone import ZoneParams, simulate_zone

if TYPE_CHECKING:
    from swarm_envs.config import SwarmConfig

__all__ = [
    "SHIPPED",
    "ModelParams",
    "ModelSpec",
    "lagrangian_min_init_radius",
    "model_names",
    "model_spec",
    "models_on",
    "models_table",
    "register_model",
    "spec_for_params",
]

#: ``simulate_<model>(params, x0, v0, *, dt, steps, goal=None, rng=None) -> (xs, vs)``,
#: each shaped ``(steps + 1, ..., N, d)`` (see ``swarm_envs.physics.simulate``).
Simulator = Callable[..., tuple[np.ndarray, np.ndarray]]

#: A step-size rule: the substeps of ``cfg.dt`` a step of the model needs
#: (``swarm_envs.envs.step_control``).
StepSizeRule = Callable[["SwarmConfig"], int]

#: What a model requires of the rest of the config: raises :class:`ValueError` naming
#: the key, the value and what is allowed.
ConfigCheck = Callable[["SwarmConfig"], None]


def _resolve(ref: Any) -> Any:
    """``ref`` itself, or the object its import path ``"module:attr"`` names."""
    if not isinstance(ref, str):
        return ref
    module, _, attr = ref.partition(":")
    return getattr(importlib.import_module(module), attr)


def _is_path(ref: Any) -> bool:
    return isinstance(ref, str) and ref.count(":") == 1 and all(ref.split(":"))


@dataclass(frozen=True)
class ModelSpec:
    """One physics model of the environments: what ``SwarmConfig.dynamics`` names.

    Attributes:
        name: the value of ``SwarmConfig.dynamics`` (a Python identifier).
        params: its parameter class, a frozen dataclass whose fields are the keys of its
            config section (validated in its ``__post_init__``; its defaults are the
            section's defaults).
        section: the config section of its parameters: a :class:`SwarmConfig` field for
            the shipped models, a key of ``SwarmConfig.model_params`` for the others.
        simulate: its simulator, ``simulate(params, x0, v0, *, dt, steps, goal=None,
            rng=None) -> (xs, vs)``, what ``swarm_envs.physics.simulate`` runs for a
            ``params`` of this type. It advances the passive physics (no control).
        adapter: how the environments step it: a subclass of
            ``swarm_envs.envs.dynamics.Dynamics``, or its import path
            ``"module:Class"``. Given ``(cfg, batch, dtype)``, it advances the batched
            state by ``dt`` with the control ``u = u_max · a`` (zero action: exactly the
            passive physics) and reports its energy statistic.
        source: the model and where it comes from, for the documentation's tables.
        action: what the control ``u_i = u_max · a_i`` does to it, for the tables.
        substeps: its step-size rule, ``substeps(cfg) -> int``, the substeps of ``dt``
            a step needs at an average start (or its import path); ``None``: nothing is
            predicted (the model controls its own step, or needs none). An environment
            refuses, when it is built, a config whose rule says more than
            ``max_substeps``.
        substeps_fixed: whether the rule's count holds for every step (its stiffness is
            fixed by the parameters) rather than for an average start; such a model's
            adapter takes that many substeps (``Dynamics.fixed_substeps``).
        backends: the cores that implement it (``SwarmConfig.backend`` values); always
            ``"numpy"``, the reference. The other cores refuse it with a reason.
        baseline: the name, in ``agents.CONTROLLERS``, of its analytic baseline
            controller (what ``make_controller("analytic", env)`` builds); ``None``:
            none, and an evaluation compares with the task's simple controllers only.
        applies_masks: whether its adapter honours the agents' ``present`` and
            ``mobile`` masks, so that agents can be removed, frozen, absent or join
            (``perturbations``); the other models take passive failures and noise only.
        integrators: the values of ``SwarmConfig.integrator`` its adapter honours;
            ``SwarmConfig`` refuses the others for it. Always the default,
            ``"semi_implicit_euler"``, which also stands for the model's own update where
            it has one (the zone model's turn, the Lagrangian model's safe substep).
        check: what it requires of the rest of the config, ``check(cfg)``, run last by
            ``SwarmConfig``'s validation; ``None``: nothing.
    """

    name: str
    params: type
    section: str
    simulate: Simulator
    adapter: type | str
    source: str
    action: str
    substeps: StepSizeRule | str | None = None
    substeps_fixed: bool = False
    backends: tuple[str, ...] = ("numpy",)
    baseline: str | None = None
    applies_masks: bool = False
    integrators: tuple[str, ...] = (INTEGRATORS[0],)
    check: ConfigCheck | None = None

    def __post_init__(self) -> None:
        owner = f"ModelSpec({self.name!r})"
        for key in ("name", "section"):
            value = getattr(self, key)
            if not isinstance(value, str) or not value.isidentifier():
                raise ValueError(f"{owner}.{key} must be a Python identifier, got {value!r}")
        if not (dataclasses.is_dataclass(self.params) and isinstance(self.params, type)):
            raise ValueError(f"{owner}.params must be a dataclass type, got {self.params!r}")
        if not self.params.__dataclass_params__.frozen:  # type: ignore[attr-defined]
            raise ValueError(f"{owner}.params must be a frozen dataclass (a config section)")
        if not callable(self.simulate):
            raise ValueError(f"{owner}.simulate must be callable, got {self.simulate!r}")
        if not (isinstance(self.adapter, type) or _is_path(self.adapter)):
            raise ValueError(
                f"{owner}.adapter must be a Dynamics subclass or its path 'module:Class', "
                f"got {self.adapter!r}"
            )
        rule = self.substeps
        if not (rule is None or callable(rule) or _is_path(rule)):
            raise ValueError(
                f"{owner}.substeps must be None, a function of the config or its path "
                f"'module:function', got {rule!r}"
            )
        if self.check is not None and not callable(self.check):
            raise ValueError(f"{owner}.check must be None or callable, got {self.check!r}")
        backends = tuple(self.backends)
        if "numpy" not in backends or not all(isinstance(b, str) for b in backends):
            raise ValueError(
                f"{owner}.backends must name the cores that implement it, 'numpy' (the "
                f"reference) among them, got {self.backends!r}"
            )
        object.__setattr__(self, "backends", backends)
        integrators = tuple(self.integrators)
        if INTEGRATORS[0] not in integrators or not set(integrators) <= set(INTEGRATORS):
            raise ValueError(
                f"{owner}.integrators must name integrators of {INTEGRATORS}, "
                f"{INTEGRATORS[0]!r} among them, got {self.integrators!r}"
            )
        object.__setattr__(self, "integrators", integrators)
        if self.baseline is not None and not isinstance(self.baseline, str):
            raise ValueError(f"{owner}.baseline must be a controller name or None")
        for key in ("source", "action"):
            if not isinstance(getattr(self, key), str) or not getattr(self, key).strip():
                raise ValueError(f"{owner}.{key} must be a non-empty description")

    def adapter_class(self) -> type:
        """The adapter class (imported on first use where :attr:`adapter` is a path)."""
        return _resolve(self.adapter)

    def substep_rule(self) -> StepSizeRule | None:
        """The step-size rule (imported on first use where it is a path), or ``None``."""
        return None if self.substeps is None else _resolve(self.substeps)


class ModelParams(Mapping[str, Any]):
    """``SwarmConfig.model_params``: the parameter sections of the registered models that
    are not shipped, keyed by section name; immutable and hashable, like the config.

    >>> ModelParams({"a": 1})["a"], len(ModelParams())
    (1, 0)
    """

    __slots__ = ("_data",)

    def __init__(self, data: Mapping[str, Any] | None = None) -> None:
        self._data = dict(data or {})

    def __getitem__(self, key: str) -> Any:
        return self._data[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Mapping) and dict(self.items()) == dict(other.items())

    def __hash__(self) -> int:
        return hash(tuple(sorted(self._data.items())))

    def __repr__(self) -> str:
        return f"ModelParams({self._data!r})"


_REGISTRY: dict[str, ModelSpec] = {}


def register_model(spec: ModelSpec, *, replace: bool = False) -> ModelSpec:
    """Add ``spec`` to the registry and return it: ``dynamics=spec.name`` then runs it.

    A name or section already registered raises :class:`ValueError`, unless ``replace``
    (for a model one is editing, re-registered by re-running its file); a shipped model
    is never replaced.
    """
    if not isinstance(spec, ModelSpec):
        raise TypeError(f"register_model takes a ModelSpec, got {type(spec).__name__}")
    old = _REGISTRY.get(spec.name)
    if old is not None and (spec.name in SHIPPED or not replace):
        why = "a shipped model" if spec.name in SHIPPED else "pass replace=True to replace it"
        raise ValueError(f"dynamics {spec.name!r} is already registered ({why})")
    for other in _REGISTRY.values():
        if other.section == spec.section and other.name != spec.name:
            raise ValueError(
                f"config section {spec.section!r} is already the section of dynamics "
                f"{other.name!r}; give ModelSpec({spec.name!r}) another section"
            )
    _REGISTRY[spec.name] = spec
    return spec


def model_names() -> tuple[str, ...]:
    """The registered models' names, the shipped ones first (:data:`SHIPPED`)."""
    return tuple(_REGISTRY)


def model_spec(name: str) -> ModelSpec:
    """The entry of ``dynamics=name``; :class:`ValueError` listing the registered names
    where there is none."""
    spec = _REGISTRY.get(name) if isinstance(name, str) else None
    if spec is None:
        raise ValueError(
            f"dynamics must be one of the registered models {model_names()}, got {name!r}"
        )
    return spec


def spec_for_params(params: Any) -> ModelSpec | None:
    """The entry whose parameter class ``params`` is an instance of (``None``: none)."""
    for spec in _REGISTRY.values():
        if isinstance(params, spec.params):
            return spec
    return None


def models_on(backend: str) -> tuple[str, ...]:
    """The registered models that the core ``backend`` implements.

    >>> models_on("torch")
    ('social_potential',)
    """
    return tuple(name for name, spec in _REGISTRY.items() if backend in spec.backends)


def models_table(names: tuple[str, ...] | None = None, width: int = 88) -> str:
    """The reStructuredText table of the models ``names`` (default every registered one):
    ``dynamics``, the model and its config section, and what the control does. The
    environments' docstrings show it."""
    rows = [("``dynamics``", "model (config section)", "what the control ``u_i`` does")]
    for name in model_names() if names is None else names:
        spec = model_spec(name)
        rows.append((f'``"{name}"``', f"{spec.source} (``{spec.section}``)", spec.action))
    first = max(len(r[0]) for r in rows)
    second = 28
    third = width - first - second - 4
    rule = f"{'=' * first}  {'=' * second}  {'=' * third}"
    lines = [rule]
    for i, (a, b, c) in enumerate(rows):
        bs = textwrap.wrap(b, second) or [""]
        cs = textwrap.wrap(c, third) or [""]
        for j in range(max(len(bs), len(cs))):
            left = a if j == 0 else ""
            mid = bs[j] if j < len(bs) else ""
            right = cs[j] if j < len(cs) else ""
            lines.append(f"{left:<{first}}  {mid:<{second}}  {right}".rstrip())
        if i == 0:
            lines.append(rule)
    lines.append(rule)
    return "\n".join(lines)


# --------------------------------------------------------------------------- shipped


def lagrangian_min_init_radius(params: LagrangianParams, n_agents: int, dim: int) -> float:
    """The start radius at or below which ``n_agents`` Lagrangian bins can never fit.

    The model needs every pair apart by more than its bins' radii, ``|x_i − x_j| >
    r_i + r_j`` (``R_ij > 0``). In a ball of radius ``R`` that needs ``R > (r_i + r_j)/2``
    for the two largest bins and, the bins being disjoint inside the ball grown by the
    largest radius, ``Σ_i r_i^d < (R + max_i r_i)^d``; with point bins (``r = 0``) still
    ``R > 0``. A radius above this bound can still be too tight for random starts: the
    environments then refuse it when they are built (see ``docs/inputs.md``).

    >>> lagrangian_min_init_radius(LagrangianParams(r=0.0), 10, 2)
    0.0
    >>> lagrangian_min_init_radius(LagrangianParams(r=1.0), 2, 2)
    1.0
    """
    if n_agents < 2:
        return 0.0
    r = np.sort(np.diagonal(params.arrays(n_agents, dim)["r_sum"]) / 2.0)
    pair = float(r[-1] + r[-2]) / 2.0
    volume = float((r**dim).sum() ** (1.0 / dim) - r[-1])
    return max(0.0, pair, volume)


def _check_lagrangian(cfg: SwarmConfig) -> None:
    """The Lagrangian model's per-agent arrays fit ``n_agents``, and its bins fit the
    start disc, which ``init_radius`` sets (its start checks read it)."""
    owner = type(cfg).__name__
    try:
        cfg.lagrangian.arrays(cfg.n_agents, cfg.dim)
    except ValueError as err:
        raise ValueError(f"{owner}.lagrangian: {err}") from None
    if cfg.init_density is not None:
        raise ValueError(
            f"{owner}.init_density must be None with dynamics='lagrangian' (its start "
            f"checks read init_radius), got {cfg.init_density!r}"
        )
    if cfg.n_agents > 1:
        low = lagrangian_min_init_radius(cfg.lagrangian, cfg.n_agents, cfg.dim)
        if not cfg.init_radius > low:
            raise ValueError(
                f"{owner}.init_radius must be in ({low:g}, inf) with dynamics='lagrangian': "
                f"{cfg.n_agents} agents start in a disc of this radius with non-overlapping "
                f"bins (lagrangian.r), got {cfg.init_radius!r}"
            )


_ADAPTERS = "swarm_envs.envs.dynamics"
_RULES = "swarm_envs.envs.step_control"

#: The models shipped with the package, in the order of ``SwarmConfig.dynamics``'s
#: documentation; the first is the default.
_SHIPPED_SPECS = (
    ModelSpec(
        name="social_potential",
        params=SocialPotentialParams,
        section="physics",
        simulate=simulate,
        adapter=f"{_ADAPTERS}:SocialPotentialDynamics",
        source="social potential, Mabrouk & McInnes",
        action="a force added to ``F_i`` (Mabrouk & McInnes eq. 13)",
        substeps=f"{_RULES}:social_potential_substeps",
        backends=("numpy", "cutoff", "native", "torch"),
        baseline="potential",
        applies_masks=True,
        integrators=INTEGRATORS,
    ),
    ModelSpec(
        name="zone",
        params=ZoneParams,
        section="zone",
        simulate=simulate_zone,
        adapter=f"{_ADAPTERS}:ZoneDynamics",
        source="Couzin's zone model, Naterop §4.1",
        action="a bias added to the unit desired direction before the turn, ``d̂_i + u_i`` "
        "(Naterop eqs. 3–6; ``u_i = ω ĝ_i`` is the informed-individual rule)",
        baseline="informed",
    ),
    ModelSpec(
        name="piecewise",
        params=PiecewiseParams,
        section="piecewise",
        simulate=simulate_piecewise,
        adapter=f"{_ADAPTERS}:PiecewiseDynamics",
        source="Viscido's piecewise force model, Naterop §4.2",
        action="a force added to ``Σ F(ρ_ij) u_ij + ξ_i − β v_i`` (Naterop eq. 15)",
        substeps=f"{_RULES}:piecewise_substeps",
        substeps_fixed=True,
        baseline="goal_force",
    ),
    ModelSpec(
        name="lagrangian",
        params=LagrangianParams,
        section="lagrangian",
        simulate=simulate_lagrangian,
        adapter=f"{_ADAPTERS}:LagrangianDynamics",
        source="Lagrangian gradient model, Vanualailai & Sharma",
        action="a velocity added to ``−α_i ∂L/∂x_i`` (Vanualailai & Sharma eq. 7); the "
        "safe substep keeps every bin pair apart (``R_ij > 0``) whatever the action",
        baseline="lyapunov",
        check=_check_lagrangian,
    ),
)

#: The names of the shipped models (``swarm_envs.config.DYNAMICS``); the first is the
#: default. Each has its own section of :class:`~swarm_envs.config.SwarmConfig`.
SHIPPED: tuple[str, ...] = ()
for _spec in _SHIPPED_SPECS:
    register_model(_spec)
SHIPPED = model_names()
