"""The contract between Python and the C step, generated from the config dataclasses.

The C step reads its parameters from a struct, ``StepParams``, whose fields, C header
and ctypes mirror are all generated here from one list, :func:`step_fields`, which is
itself derived from the dataclasses:

- every field of :class:`~swarm_envs.physics.SocialPotentialParams`, as
  ``physics_<name>`` (a new physics parameter enters the struct by itself);
- the :class:`~swarm_envs.config.SwarmConfig` fields of :data:`KERNEL_CONFIG_FIELDS`,
  typed from the dataclass's annotations;
- a few derived values (:data:`DERIVED`), each with the function that computes it.

Generated too, each from its one Python definition:

- the output columns' indices (``PK_<name>``, :data:`PACKED_COLUMNS`: the statistics in
  the order of ``STAT_KEYS`` from :mod:`swarm_envs.envs.task.statistics`, then
  ``PK_effort``, ``PK_over_cap``, ``PK_needed``);
- the agents' statuses (``STATUS_<name>``, from
  :mod:`~swarm_envs.envs.task.agent_status`), the kernel's flag bits ``AG_*`` and the
  flags of each status (``STATUS_FLAGS``, from
  :func:`~swarm_envs.envs.task.agent_status.masks`);
- the return codes (``STEP_<name>``, :class:`StepCode`) and the flag ``STEP_UNSOUND``
  (:data:`UNSOUND`); :func:`step_error` turns a code into its exception by name.

The generated header is part of the build (and of the cache key); a copy of it is
committed as ``include/step_params.h`` for the builds at install, which run without the
package's dependencies (``python -m swarm_envs.envs.cores.native.write_header`` rewrites
it; a test holds it equal to :func:`header`). The C code refers to
fields, columns, statuses and codes by name, so one renamed or removed on the Python
side fails the build. The other direction: the kernel declares the physics parameters,
statistics and observation layout it implements (:class:`KernelInfo`, read from the
library), and :func:`unsupported` refuses a config that needs more than that, naming
what.

Every :class:`~swarm_envs.config.SwarmConfig` field is either read by the kernel or
listed in :data:`HOST_CONFIG_FIELDS` (handled in Python, or irrelevant to the social
potential step); a field in neither makes :func:`unsupported` refuse every config, so a
new config field cannot be silently ignored by the C step.
"""

from __future__ import annotations

import ctypes
import dataclasses
import enum
import hashlib
import math
import typing
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from swarm_envs.config import SwarmConfig
from swarm_envs.envs.common import NON_FINITE_ACTIONS
from swarm_envs.envs.task import (
    OBS_BOUND,
    STAT_KEYS,
    agent_status,
    observation_size,
    ranked_neighbors,
)
from swarm_envs.envs.task.observation import layout
from swarm_envs.envs.task.statistics import mill_speed_scale
from swarm_envs.metrics import CENTRE_RTOL
from swarm_envs.models import SHIPPED, model_spec, models_on
from swarm_envs.physics import SocialPotentialParams
from swarm_envs.physics.integrators import STEP_SAFETY
from swarm_envs.physics.social_potential import RHO_FLOOR

__all__ = [
    "AGENT_FLAGS",
    "AGENT_STATUSES",
    "DERIVED",
    "HOST_CONFIG_FIELDS",
    "KERNEL_CONFIG_FIELDS",
    "PACKED_COLUMNS",
    "STATUS_MASKS",
    "UNSOUND",
    "Field",
    "KernelInfo",
    "StepCode",
    "header",
    "layout_hash",
    "params_struct",
    "status_flags",
    "step_error",
    "step_fields",
    "step_params",
    "unsupported",
]

#: The :class:`SwarmConfig` fields the C step reads (as struct fields of the same name).
KERNEL_CONFIG_FIELDS = (
    "n_agents",
    "dim",
    "n_neighbors",
    "dt",
    "u_max",
    "collision_radius",
    "obs_goal_scale",
    "obs_neighbor_scale",
    "obs_velocity_scale",
    "goal_in_physics",
    "max_substeps",
    "observe_status",
)

_KEYS = {f.name for f in dataclasses.fields(SwarmConfig)}

#: The :class:`SwarmConfig` fields the C step does not read, and why.
HOST_CONFIG_FIELDS = {
    "physics": "expanded into the physics_* fields",
    "dynamics": "the models whose ModelSpec.backends has 'native' only (checked)",
    "integrator": "as the derived `implicit_damping`; velocity_verlet refused (checked)",
    **{
        model_spec(name).section: "another model's section"
        for name in SHIPPED
        if "native" not in model_spec(name).backends and model_spec(name).section in _KEYS
    },
    "model_params": "the other registered models' sections (refused)",
    "init_radius": "starts are drawn in Python",
    "init_speed": "starts are drawn in Python",
    "init_density": "starts are drawn in Python",
    "goal_distance_scale": "starts are drawn in Python; as the derived `arrival_radius`",
    "goal_radius": "as the derived `arrival_radius`",
    "goal_distance_min": "starts are drawn in Python",
    "goal_distance_max": "starts are drawn in Python",
    "success_fraction": "as the derived `success_threshold`",
    "max_steps": "truncation is counted in Python",
    "reward": "the reward is combined in Python from the kernel's columns",
    "backend": "selects the core",
    "device": "the C step runs on the CPU",
    "on_unstable": "the guard after the step runs in Python (it raises, or undoes the step)",
    "perturbations": "drawn and applied in Python (PerturbedCore: the schedule, the noise, "
    "the dropout); the agents' statuses reach the kernel as an array (set_status)",
    "task": "the reward, termination, starts and a task's own success rule in Python; "
    "informed agents, a task's own statistics and observation features refused (checked)",
    "informed_fraction": "task='informed' only, which is refused",
}


class StepCode(enum.IntEnum):
    """What the C step returns, less the flag :data:`UNSOUND` (``STEP_<name>`` in C).

    The errors are checked before anything is written (``NON_FINITE_ACTIONS``,
    ``TOO_MANY_NEIGHBOURS``) or while the swarms are stepped (``NO_SCRATCH``: a thread
    without its scratch memory skips its swarms); :func:`step_error` gives each one's
    exception.
    """

    OK = 0
    NO_SCRATCH = 1
    """A thread could not allocate its scratch memory."""
    TOO_MANY_NEIGHBOURS = 2
    """The config ranks more neighbours than the kernel's ``kmax``
    (:func:`unsupported` refuses such a config up front)."""
    NON_FINITE_ACTIONS = 3
    """An action of the swarms stepped is NaN or infinite."""


#: Or'ed into the C step's return value where a swarm of the call went over the cap or
#: wrote a non-finite column: only then does the caller run its guard (the exact check,
#: :func:`~swarm_envs.envs.common.unstable_swarms`). A bit above every :class:`StepCode`.
UNSOUND = 1 << max(StepCode).bit_length()

_STEP_ERRORS: dict[StepCode, tuple[type[Exception], str]] = {
    StepCode.NO_SCRATCH: (MemoryError, "the C step could not allocate its scratch memory"),
    StepCode.TOO_MANY_NEIGHBOURS: (
        RuntimeError,
        "the C step was asked to rank more neighbours than it can (KernelInfo.kmax); "
        "such a config must be refused by contract.unsupported",
    ),
    StepCode.NON_FINITE_ACTIONS: (ValueError, NON_FINITE_ACTIONS),
}


def step_error(code: int) -> Exception:
    """The exception for the C step's return value ``code`` (:data:`UNSOUND` ignored),
    by its :class:`StepCode`; an unknown code is a :class:`RuntimeError` naming it."""
    try:
        kind, message = _STEP_ERRORS[StepCode(code & ~UNSOUND)]
    except (KeyError, ValueError):
        return RuntimeError(f"the C step returned the unknown code {code}")
    return kind(message)


#: The agents' statuses by name (:mod:`~swarm_envs.envs.task.agent_status`), in C as
#: ``STATUS_<name>``; their values are the module's.
AGENT_STATUSES = ("ACTIVE", "FAILED", "FROZEN", "ABSENT")

#: The kernel's flag bits of an agent (``AG_<name>`` in C), each one of the masks of
#: :func:`~swarm_envs.envs.task.agent_status.masks`: in the physics (``present``),
#: integrated and a member of the swarm (``mobile``), observed as active
#: (``controlled``).
AGENT_FLAGS = {"PRESENT": "present", "MOBILE": "mobile", "ACTIVE": "controlled"}


def status_flags() -> dict[str, tuple[str, ...]]:
    """The flags ``AG_*`` of each status (``STATUS_FLAGS`` in C), from
    :func:`~swarm_envs.envs.task.agent_status.masks`."""
    codes = np.array([getattr(agent_status, name) for name in AGENT_STATUSES])
    if sorted(codes.tolist()) != list(range(len(codes))):
        named = dict(zip(AGENT_STATUSES, codes.tolist(), strict=True))
        raise RuntimeError(f"the agent statuses {named} are not numbered 0 .. n - 1")
    m = agent_status.masks(codes)._asdict()
    return {
        name: tuple(flag for flag, mask in AGENT_FLAGS.items() if m[mask][i])
        for i, name in enumerate(AGENT_STATUSES)
    }


#: Columns of the kernel's per-swarm output: the statistics, the actions' effort, then
#: the step-size control's ``over_cap`` (1 where the step needed more substeps than
#: ``max_substeps``) and ``needed`` (how many it would have taken, for the error message).
PACKED_COLUMNS = (*STAT_KEYS, "effort", "over_cap", "needed")


@dataclass(frozen=True)
class Field:
    """One field of ``StepParams``: its C name and type, and how a config gives it."""

    name: str
    ctype: str  # "int64_t" or "double"
    value: Callable[[SwarmConfig, np.dtype], float]
    source: str


def _eps(dtype: np.dtype) -> float:
    return float(np.finfo(dtype).eps)


#: Derived fields: (name, C type, value(cfg, dtype), what it is).
DERIVED: tuple[tuple[str, str, Callable[[SwarmConfig, np.dtype], float], str], ...] = (
    ("k_real", "int64_t", lambda c, dt: min(c.n_neighbors, c.n_agents - 1), "observed neighbours"),
    ("k_rank", "int64_t", lambda c, dt: max(ranked_neighbors(c), 0), "ranked neighbours"),
    ("obs_dim", "int64_t", lambda c, dt: observation_size(c), "observation size"),
    ("arrival_radius", "double", lambda c, dt: c.arrival_radius, "arrived within this"),
    (
        "cruise_speed",
        "double",
        lambda c, dt: mill_speed_scale(c),
        "v0 of self-propulsion, floored (mill_order; 0 without)",
    ),
    (
        "physics_goal",
        "int64_t",
        lambda c, dt: int(c.passive_sink),
        "the sink acts passively",
    ),
    (
        "success_threshold",
        "double",
        lambda c, dt: c.success_fraction - 1e-9,  # success_count's rule
        "success: arrived members / members at least this (success_count's rule)",
    ),
    ("obs_bound", "double", lambda c, dt: OBS_BOUND, "observation clip"),
    ("rho_floor", "double", lambda c, dt: RHO_FLOOR, "distance floor"),
    (
        "implicit_damping",
        "int64_t",
        lambda c, dt: int(c.integrator == "implicit_damping_euler"),
        "integrator='implicit_damping_euler' (else semi-implicit Euler)",
    ),
    (
        "centre_tol",
        "double",
        lambda c, dt: CENTRE_RTOL * _eps(dt) * math.sqrt(c.n_agents),
        "centring tolerance / max |x|",
    ),
)

_CTYPE_OF = {int: "int64_t", bool: "int64_t", float: "double"}


def step_fields() -> tuple[Field, ...]:
    """The fields of ``StepParams`` in order: ``batch``, the config's, the physics', the
    derived ones."""
    out = [Field("batch", "int64_t", lambda c, dt: 0, "swarms in this call")]
    hints = typing.get_type_hints(SwarmConfig)
    for name in KERNEL_CONFIG_FIELDS:
        ctype = _CTYPE_OF[hints[name]]
        out.append(Field(name, ctype, _getter(name), f"SwarmConfig.{name}"))
    for f in dataclasses.fields(SocialPotentialParams):
        out.append(
            Field(f"physics_{f.name}", "double", _physics_getter(f.name), f"physics.{f.name}")
        )
    for name, ctype, value, what in DERIVED:
        out.append(Field(name, ctype, value, f"derived: {what}"))
    return tuple(out)


def _getter(name: str) -> Callable[[SwarmConfig, np.dtype], float]:
    return lambda cfg, dtype: getattr(cfg, name)


def _physics_getter(name: str) -> Callable[[SwarmConfig, np.dtype], float]:
    return lambda cfg, dtype: getattr(cfg.physics, name)


def _header_body() -> list[str]:
    lines = [
        "/* Generated by swarm_envs.envs.cores.native.contract from the config dataclasses.",
        " * Do not edit: it is written into the build of every C step. */",
        "#ifndef SWARM_ENVS_STEP_PARAMS_H",
        "#define SWARM_ENVS_STEP_PARAMS_H",
        "#include <stdint.h>",
        "typedef struct {",
    ]
    for f in step_fields():
        lines.append(f"    {f.ctype} {f.name}; /* {f.source} */")
    lines.append("} StepParams;")
    columns = ", ".join(f"PK_{name}" for name in PACKED_COLUMNS)
    lines.append(f"enum {{ {columns}, PK_SIZE }};")
    codes = ", ".join(f"STEP_{c.name} = {c.value}" for c in StepCode)
    lines.append(f"enum {{ {codes}, STEP_UNSOUND = {UNSOUND} }};")
    statuses = ", ".join(f"STATUS_{n} = {getattr(agent_status, n)}" for n in AGENT_STATUSES)
    lines.append(f"enum {{ {statuses}, STATUS_COUNT = {len(AGENT_STATUSES)} }};")
    bits = ", ".join(f"AG_{name} = {1 << i}" for i, name in enumerate(AGENT_FLAGS))
    lines.append(f"enum {{ {bits} }};")
    table = ", ".join(
        f"[STATUS_{name}] = {' | '.join(f'AG_{f}' for f in flags) or '0'}"
        for name, flags in status_flags().items()
    )
    lines.append(f"#define STATUS_FLAGS {{ {table} }}")
    # the numerator of the step-size rule, 4 · STEP_SAFETY, exactly as Python rounds it
    lines.append(f"#define STEP_EDGE_NUMERATOR {float.hex(4.0 * STEP_SAFETY)}")
    return lines


def layout_hash() -> int:
    """A hash of the generated contract; the library returns it from
    ``fused_step_layout()``, and a library built for another contract is not loaded."""
    return int(hashlib.sha256("\n".join(_header_body()).encode()).hexdigest()[:15], 16)


def header() -> str:
    """The generated C header: ``StepParams``, the ``PK_*`` columns, the return codes,
    the agents' statuses and flags, the layout hash."""
    lines = [*_header_body(), f"#define STEP_LAYOUT_HASH {layout_hash()}LL", "#endif"]
    return "\n".join(lines) + "\n"


def header_path() -> Path:
    """The committed copy of :func:`header` that the builds at install compile against."""
    return Path(__file__).resolve().parent / "include" / "step_params.h"


def write_header(path: Path | None = None) -> Path:
    """Write :func:`header` to ``path`` (default :func:`header_path`); returns the path."""
    path = path or header_path()
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(header())
    return path


def params_struct() -> type[ctypes.Structure]:
    """The ctypes mirror of ``StepParams``, from the same field list."""
    types = {"int64_t": ctypes.c_int64, "double": ctypes.c_double}
    return type(
        "StepParams",
        (ctypes.Structure,),
        {"_fields_": [(f.name, types[f.ctype]) for f in step_fields()]},
    )


def step_params(cfg: SwarmConfig, dtype: Any) -> ctypes.Structure:
    """``StepParams`` for ``cfg`` and a state of ``dtype`` (``batch`` set per call)."""
    dtype = np.dtype(dtype)
    struct = params_struct()()
    for f in step_fields():
        value = f.value(cfg, dtype)
        setattr(struct, f.name, int(value) if f.ctype == "int64_t" else float(value))
    return struct


@dataclass(frozen=True)
class KernelInfo:
    """What a built C step implements (its own declarations, read from the library).

    Attributes:
        physics: the ``SocialPotentialParams`` fields its force law uses.
        statistics: the statistics it writes (the others are computed in Python).
        obs_layouts: the observation layouts it writes (each compared with
            :func:`~swarm_envs.envs.task.observation.layout` of a config).
        kmax: the most neighbours it ranks.
        statuses: the agents' masks it applies where agents have statuses
            (:mod:`~swarm_envs.envs.task.agent_status`): ``present``, ``mobile``,
            ``members``, ``active``; all four for a config that needs statuses.
    """

    physics: tuple[str, ...]
    statistics: tuple[str, ...]
    obs_layouts: tuple[str, ...]
    kmax: int
    statuses: tuple[str, ...] = ()


#: The masks of agent statuses a kernel must apply to run a config that needs statuses.
STATUS_MASKS = ("present", "mobile", "members", "active")


def unsupported(cfg: SwarmConfig, kernel: KernelInfo) -> str | None:
    """Why the C step cannot run ``cfg`` (``None`` if it can), naming what it lacks."""
    if "native" not in model_spec(cfg.dynamics).backends:
        names = " or ".join(f"{name!r}" for name in models_on("native"))
        return f"supports dynamics={names} only, got {cfg.dynamics!r}"
    if cfg.integrator not in ("semi_implicit_euler", "implicit_damping_euler"):
        return (
            "supports integrator='semi_implicit_euler' or 'implicit_damping_euler' only, "
            f"got {cfg.integrator!r}"
        )
    if cfg.device != "cpu":
        return f"runs on the CPU only, got device={cfg.device!r}"
    if cfg.informs_agents:
        return "does not write the informed agents' observation (task='informed')"
    if cfg.task_spec.statistics:
        return f"does not compute task {cfg.task!r}'s own statistics"
    if cfg.task_spec.features:
        features = ", ".join(f.name for f in cfg.task_spec.features)
        return f"does not write task {cfg.task!r}'s observation features ({features})"
    known = set(KERNEL_CONFIG_FIELDS) | set(HOST_CONFIG_FIELDS)
    for f in dataclasses.fields(SwarmConfig):
        if f.name not in known:
            return f"config field {f.name!r} has no meaning in the C step yet"
    default = SocialPotentialParams()
    for f in dataclasses.fields(SocialPotentialParams):
        if f.name not in kernel.physics and getattr(cfg.physics, f.name) != getattr(
            default, f.name
        ):
            return f"physics.{f.name} is not implemented in the C step"
    if layout(cfg) not in kernel.obs_layouts:
        return f"writes the observation layouts {kernel.obs_layouts!r}, not {layout(cfg)!r}"
    if cfg.needs_statuses:  # set_status is called
        missing = [mask for mask in STATUS_MASKS if mask not in kernel.statuses]
        if missing:
            return f"does not apply the agents' statuses ({', '.join(missing)})"
    if ranked_neighbors(cfg) > kernel.kmax:
        return (
            f"ranks at most {kernel.kmax} neighbours, got n_neighbors={cfg.n_neighbors} "
            f"with n_agents={cfg.n_agents}"
        )
    return None
