"""The tasks of the swarm environments: one registry, the shipped tasks its first entries.

One environment class runs every task; ``SwarmConfig.task`` names one. A task is a
:class:`TaskSpec`: what the swarm must do, written once over the array namespace
(:mod:`swarm_envs._array`) so that every core executes it. :func:`register_task` adds
one, from inside the package or from a user's own file (``docs/tasks.md``, "Adding a
task"); :func:`task_spec` looks one up by name, :func:`task_names` lists them. The
package registers three (:data:`TASKS`), each with its Gymnasium id and PettingZoo
module (:data:`TASK_IDS`):

=============  ===============================  =============================================
``task``       registered id                    what the swarm must do
=============  ===============================  =============================================
navigation     ``swarm_envs/SwarmNav-v0``       gather inside the goal radius (every agent
                                                observes the goal)
informed       ``swarm_envs/SwarmInformed-v0``  the same, when only ``informed_fraction`` of
                                                the agents observe the goal; the others see
                                                their neighbours and which of them are
                                                informed (Couzin's informed individuals)
mill           ``swarm_envs/SwarmMill-v0``      reach the goal and circle it: a mill about
                                                the goal of a self-propelled swarm
=============  ===============================  =============================================

A task's defaults (:func:`task_defaults`: its ``defaults`` and its reward terms' default
weights) lie under whatever the caller gives: the registered ids, the PettingZoo modules,
:func:`~swarm_envs.config.load_swarm_config` and a YAML file with ``task:`` all apply
them, so ``gym.make("swarm_envs/SwarmMill-v0")`` is the mill with its self-propelled
physics, and ``physics={"alpha": 2.0}`` changes only that value. A
:class:`~swarm_envs.config.SwarmConfig` built directly takes the dataclass defaults;
:func:`task_config` builds one with the task's defaults.

What a task declares, and who executes it:

- ``reward_terms``: :class:`~swarm_envs.envs.task.reward.RewardTerm` s, each with its
  default weight; the reward is ``Σ sign · weight · value`` over them
  (:func:`~swarm_envs.envs.task.reward.reward`). A term's name is its weight's key in
  the config's ``reward`` section and one concept: two tasks may share a term (the same
  object) but not a name.
- ``statistics``: :class:`~swarm_envs.envs.task.statistics.Statistic` s reported in
  ``info`` after the common ones (``STAT_KEYS``), which the reward terms read.
- ``features``: :class:`~swarm_envs.envs.task.observation.ObservationFeature` s appended
  to each agent's own features (and, where ``neighbors``, to each neighbour slot).
- ``success`` and ``terminates_on_success``: the ``success`` statistic's rule (default:
  ``success_fraction`` of the members within the arrival radius) and whether success
  ends the episode (the mill holds it instead).
- ``start``: the law of the starts ``(x, v, goal)``, where the default's does not fit.
- ``informed``: only ``informed_fraction`` of the agents observe the goal, drawn per
  episode, and the observation says who (the informed task's).

The numpy and cut-off cores execute every declaration; the compiled torch core every one
but a task's own statistics and the informed agents; the C step the reward terms, the
success rule, the episode end and the start law, and refuses a task with its own
observation features or statistics (each core's ``unsupported`` says why; the env then
falls back to one that runs it, with a warning).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

    from swarm_envs._array import ArrayNamespace
    from swarm_envs.config import SwarmConfig
    from swarm_envs.envs.task.observation import ObservationFeature
    from swarm_envs.envs.task.reward import RewardTerm
    from swarm_envs.envs.task.statistics import Frame, Statistic

#: The speed (a fraction of the cruise speed ``v₀``) above which the members within the
#: arrival radius count as milling: the mill task succeeds while they circle the goal at
#: least this fast and ``success_fraction`` of the members have arrived.
MILL_SUCCESS_SPEED = 0.5

#: A task's name: a Python identifier (it is a config value and a reward-section key).
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

StartLaw = Callable[["SwarmConfig", "np.random.Generator", int], tuple[Any, Any, Any]]
"""``start(cfg, rng, n) -> (x (n, N, d), v (n, N, d), goal (n, d))``, float64 arrays."""

SuccessRule = Callable[["Frame", "SwarmConfig", "ArrayNamespace"], Any]
"""``success(frame, cfg, xp) -> (B,)``: 1.0 where the task succeeds, else 0.0, over the
array namespace ``xp`` (:mod:`swarm_envs._array`)."""


@dataclass(frozen=True)
class TaskSpec:
    """What a task is: the declarations every core executes (module docstring).

    Attributes:
        name: the value of ``SwarmConfig.task`` (an identifier).
        doc: what the swarm must do, one sentence (the env docstring lists it).
        reward_terms: the reward's terms, each with its default weight; the shipped
            terms (:data:`~swarm_envs.envs.task.reward.REWARD_TERMS`) may be reused, with
            another default weight through ``dataclasses.replace``.
        statistics: statistics of this task beyond the common ones, in ``info`` after
            them; reward terms read them from ``stats``, ``prev`` and ``start``.
        features: per-agent observation features after the agent's goal offset and
            velocity (and, where ``neighbors``, after each neighbour slot's entries).
        success: ``success(frame, cfg, xp) -> (B,)`` 1.0/0.0, the ``success``
            statistic; ``None``: ``success_fraction`` of the members have arrived.
        success_doc: what ``success`` means, one phrase (``None``: the default's).
        terminates_on_success: whether success ends the episode (``False``: the task
            holds a state and is truncated after ``max_steps``, as the mill).
        start: the starts' law (:data:`StartLaw`), ``None``: agents uniform in the start
            disc, the goal at a random bearing
            (:func:`~swarm_envs.envs.common.draw_starts`).
        informed: only ``informed_fraction`` of each swarm observe the goal, drawn per
            episode; the others see a zero goal offset (the observation's ``informed``
            flag feature belongs in ``features``).
        check: ``check(cfg) -> reason | None``: what the task needs of the rest of the
            config (``None`` where it runs on any).
        defaults: config keys this task sets beneath the caller's values (sections as
            mappings, merged key by key); its reward weights come from the terms.
        env_id: the Gymnasium id :func:`register_task` registers (``None``: none).
        module: the PettingZoo module that runs the task (``None``: none; every task
            runs through ``swarm_nav_v0`` with ``task=``).
    """

    name: str
    doc: str
    reward_terms: tuple[RewardTerm, ...]
    statistics: tuple[Statistic, ...] = ()
    features: tuple[ObservationFeature, ...] = ()
    success: SuccessRule | None = None
    success_doc: str | None = None
    terminates_on_success: bool = True
    start: StartLaw | None = None
    informed: bool = False
    check: Callable[[SwarmConfig], str | None] | None = None
    defaults: Mapping[str, Any] = field(default_factory=dict)
    env_id: str | None = None
    module: str | None = None

    def __post_init__(self) -> None:
        owner = f"TaskSpec({self.name!r})"
        if not isinstance(self.name, str) or not _NAME.match(self.name):
            raise ValueError(f"TaskSpec.name must be an identifier, got {self.name!r}")
        for attr in ("reward_terms", "statistics", "features"):
            value = getattr(self, attr)
            if not isinstance(value, (tuple, list)):
                raise ValueError(f"{owner}.{attr} must be a tuple, got {type(value).__name__}")
            object.__setattr__(self, attr, tuple(value))
        if not self.reward_terms:
            raise ValueError(f"{owner}.reward_terms must name at least one term")
        for attr, kind in (("reward_terms", "RewardTerm"), ("statistics", "Statistic")):
            if any(type(item).__name__ != kind for item in getattr(self, attr)):
                raise ValueError(f"{owner}.{attr} must hold {kind}s")
            names: list[str] = [item.name for item in getattr(self, attr)]
            repeated = sorted({n for n in names if names.count(n) > 1})
            if repeated:
                raise ValueError(f"{owner}.{attr}: names given twice: {', '.join(repeated)}")
        if not isinstance(self.defaults, Mapping):
            raise ValueError(f"{owner}.defaults must be a mapping of config keys")
        if "task" in self.defaults or "reward" in self.defaults:
            raise ValueError(
                f"{owner}.defaults must not set 'task' or 'reward' (the reward's default "
                "weights are the terms' own)"
            )
        if not isinstance(self.terminates_on_success, bool) or not isinstance(self.informed, bool):
            raise ValueError(f"{owner}: terminates_on_success and informed must be true or false")

    @property
    def term_names(self) -> tuple[str, ...]:
        """The names of the reward terms, in order (the keys of ``reward``)."""
        return tuple(t.name for t in self.reward_terms)

    def reward_defaults(self) -> dict[str, float]:
        """The default weight of every term of the config's ``reward`` section: each
        term's own, and 0 for a shipped term this task does not have."""
        from swarm_envs.envs.task.reward import REWARD_TERMS

        out = {t.name: 0.0 for t in REWARD_TERMS}
        out.update({t.name: float(t.weight) for t in self.reward_terms})
        return out


_REGISTRY: dict[str, TaskSpec] = {}
#: The registered tasks' own reward terms by name (the shipped ones are REWARD_TERMS).
_TERMS: dict[str, RewardTerm] = {}
#: The package's tasks, once registered; ``None`` before, ``()`` while loading.
_SHIPPED: tuple[str, ...] | None = None


def _load_shipped() -> None:
    """Register the package's tasks (once; the registry's first entries)."""
    global _SHIPPED
    if _SHIPPED is not None:
        return
    _SHIPPED = ()
    from swarm_envs.envs.task.shipped import SHIPPED_TASKS

    for spec in SHIPPED_TASKS:
        _register(spec, replace=False)
    _SHIPPED = tuple(spec.name for spec in SHIPPED_TASKS)


def _shipped_terms() -> dict[str, RewardTerm]:
    from swarm_envs.envs.task.reward import REWARD_TERMS

    return {t.name: t for t in REWARD_TERMS}


def _check_terms(spec: TaskSpec) -> None:
    """A term may reuse a shipped or another task's term, not its name for another; a
    task's own statistics follow the common ones under other names."""
    from swarm_envs.envs.task.statistics import STAT_KEYS

    taken = sorted(s.name for s in spec.statistics if s.name in STAT_KEYS)
    if taken:
        raise ValueError(
            f"task {spec.name!r}: its statistics {', '.join(taken)} are common statistics' "
            f"names (common: {', '.join(STAT_KEYS)})"
        )
    shipped = _shipped_terms()
    for term in spec.reward_terms:
        other, owner = shipped.get(term.name), "the package's"
        for s in _REGISTRY.values():
            if other is None and s.name != spec.name:
                other = next((t for t in s.reward_terms if t.name == term.name), None)
                owner = f"task {s.name!r}'s"
        if other is not None and other.value is not term.value:
            raise ValueError(
                f"task {spec.name!r}: reward term {term.name!r} is {owner} term's name; a "
                "term's name is its weight's key: name yours otherwise, or reuse that term "
                "(dataclasses.replace gives it another default weight)"
            )


def _register(spec: TaskSpec, replace: bool) -> None:
    old = _REGISTRY.get(spec.name)
    if old is spec:
        return
    if old is not None and (spec.name in (_SHIPPED or ()) or not replace):
        why = "one of the package's" if spec.name in (_SHIPPED or ()) else "registered already"
        raise ValueError(
            f"task {spec.name!r} is {why}; give yours another name"
            + ("" if spec.name in (_SHIPPED or ()) else " or pass replace=True")
        )
    _check_terms(spec)
    if spec.env_id is not None:
        _register_gymnasium(spec.name, spec.env_id)
    _REGISTRY[spec.name] = spec
    _collect_terms()


def _collect_terms() -> None:
    shipped = _shipped_terms()
    _TERMS.clear()
    for s in _REGISTRY.values():
        for term in s.reward_terms:
            if term.name not in shipped:
                _TERMS.setdefault(term.name, term)


def _register_gymnasium(name: str, env_id: str) -> None:
    from gymnasium.envs.registration import register, registry

    task = {} if name == "navigation" else {"task": name}
    if env_id in registry:
        if dict(registry[env_id].kwargs) != task:
            raise ValueError(
                f"task {name!r}: the Gymnasium id {env_id!r} is registered for another environment"
            )
        return
    register(
        id=env_id,
        entry_point="swarm_envs.envs.adapters.swarm_nav:SwarmNavEnv",
        vector_entry_point="swarm_envs.envs.adapters.gym_vector:SwarmNavVectorEnv",
        kwargs=task,
    )


def register_task(spec: TaskSpec, *, replace: bool = False) -> TaskSpec:
    """Add ``spec`` to the registry (and its ``env_id`` to Gymnasium's); returns it.

    Registering the same object again does nothing; another task under a registered
    name raises :class:`ValueError` unless ``replace`` (never one of the package's). A
    reward term may reuse a shipped or another task's term (the same ``value``), but
    not its name for another definition.

    >>> from swarm_envs.envs.task.reward import REWARD_TERMS
    >>> spec = TaskSpec("doc_example", "gather", reward_terms=REWARD_TERMS[:1])
    >>> register_task(spec).name, "doc_example" in task_names()
    ('doc_example', True)
    >>> unregister_task("doc_example")
    """
    if not isinstance(spec, TaskSpec):
        raise ValueError(f"register_task takes a TaskSpec, got {type(spec).__name__}")
    _load_shipped()
    _register(spec, replace)
    return spec


def unregister_task(name: str) -> None:
    """Remove the task ``name`` (and its own reward terms) from the registry; its
    Gymnasium id stays. The package's tasks cannot be removed."""
    _load_shipped()
    if name in (_SHIPPED or ()):
        raise ValueError(f"task {name!r} is one of the package's and stays registered")
    if _REGISTRY.pop(name, None) is None:
        raise ValueError(f"task {name!r} is not registered; registered: {', '.join(_REGISTRY)}")
    _collect_terms()


def task_spec(name: str) -> TaskSpec:
    """The registered task ``name``; :class:`ValueError` naming the registered ones."""
    spec = _REGISTRY.get(name) if isinstance(name, str) else None
    if spec is None:
        _load_shipped()
        spec = _REGISTRY.get(name) if isinstance(name, str) else None
    if spec is None:
        raise ValueError(f"task must be one of {task_names()}, got {name!r}")
    return spec


def task_names() -> tuple[str, ...]:
    """Every registered task's name, the package's first (in registration order)."""
    _load_shipped()
    return tuple(_REGISTRY)


def reward_term(name: str) -> RewardTerm:
    """The registered tasks' own reward term ``name`` (not a shipped one)."""
    try:
        return _TERMS[name]
    except KeyError:
        raise ValueError(
            f"no registered task has the reward term {name!r}; terms: {', '.join(_TERMS)}"
        ) from None


def task_defaults(name: str) -> dict[str, Any]:
    """The config keys task ``name`` sets beneath the caller's: its ``defaults`` and
    its ``reward`` weights (:meth:`TaskSpec.reward_defaults`)."""
    spec = task_spec(name)
    return {**spec.defaults, "reward": spec.reward_defaults()}


def _merge(base: Mapping[str, Any], top: Mapping[str, Any]) -> dict[str, Any]:
    """``top`` over ``base``; sections (mappings) are merged key by key."""
    out = dict(base)
    for key, value in top.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = _merge(out[key], value)
        else:
            out[key] = value
    return out


def with_task_defaults(data: Mapping[str, Any]) -> dict[str, Any]:
    """``data`` (config keys) over the defaults of its task (``data["task"]``, else
    navigation). An unknown task is left to the config's validation."""
    task = data.get("task", "navigation")
    if not isinstance(task, str) or task not in task_names():
        return dict(data)
    reward = data.get("reward")
    if isinstance(reward, Mapping) and isinstance(reward.get("terms"), Mapping):
        # every weight by its term's name, as the defaults give them (a saved config's
        # ``terms`` then lies over the defaults)
        flat = {k: v for k, v in reward.items() if k != "terms"}
        data = {**data, "reward": {**flat, **reward["terms"]}}
    return _merge(task_defaults(task), data)


def task_config(task: str, **overrides: Any) -> SwarmConfig:
    """A :class:`~swarm_envs.config.SwarmConfig` for ``task`` with its defaults, then
    ``overrides`` (config keys; a partial section changes only the keys it names).

    >>> cfg = task_config("mill", n_agents=12)
    >>> cfg.task, cfg.physics.alpha, cfg.goal_in_physics, cfg.n_agents
    ('mill', 0.5, True, 12)
    """
    from swarm_envs.config import load_swarm_config

    return load_swarm_config(None, {"task": task, **overrides})


def informed_count(fraction: float, n_agents: int) -> int:
    """How many of ``n_agents`` observe the goal: ``fraction · N`` rounded to the nearest
    whole agent (halves up), at least one. A range ``[0.1, 0.3]`` of 10 agents thus
    gives 1, 2 or 3 informed agents (a quarter, a half and a quarter of the episodes).

    >>> informed_count(0.1, 10), informed_count(0.3, 10), informed_count(0.05, 10)
    (1, 3, 1)
    >>> informed_count(0.24, 10), informed_count(0.25, 10)
    (2, 3)
    """
    return max(1, min(n_agents, math.floor(fraction * n_agents + 0.5 + 1e-9)))


#: The package's tasks' names, the first the default (``SwarmConfig.task``); and the
#: Gymnasium id and the defaults (:func:`task_defaults`) of each. Views of the registry,
#: made on first access (:func:`__getattr__`).
TASKS: tuple[str, ...]
TASK_IDS: dict[str, str]
TASK_DEFAULTS: dict[str, dict[str, Any]]


def __getattr__(name: str) -> Any:
    """The views of the package's tasks, derived from the registry:

    - ``TASKS``: their names, the first the default (``SwarmConfig.task``);
    - ``TASK_IDS``: the Gymnasium id of each;
    - ``TASK_DEFAULTS``: each one's :func:`task_defaults`.
    """
    if name in ("TASKS", "TASK_IDS", "TASK_DEFAULTS"):
        _load_shipped()
        specs = [_REGISTRY[n] for n in _SHIPPED or ()]
        if name == "TASKS":
            return tuple(s.name for s in specs)
        if name == "TASK_IDS":
            return {s.name: s.env_id for s in specs if s.env_id is not None}
        return {s.name: task_defaults(s.name) for s in specs}
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "MILL_SUCCESS_SPEED",
    "TASKS",
    "TASK_DEFAULTS",
    "TASK_IDS",
    "StartLaw",
    "SuccessRule",
    "TaskSpec",
    "informed_count",
    "register_task",
    "reward_term",
    "task_config",
    "task_defaults",
    "task_names",
    "task_spec",
    "unregister_task",
    "with_task_defaults",
]
