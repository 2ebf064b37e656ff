"""The one input rule of every SwarmNav API (specified in ``docs/inputs.md``).

The Gymnasium env, the PettingZoo parallel and AEC envs and the SB3 ``VecEnv`` check
what they are given with these helpers, so that each API accepts and refuses the same
values with the same messages:

* **Actions** are real numeric arrays of exactly the declared shape (rank included):
  a float or integer dtype (integers are numbers and are cast); bool, complex, object,
  string and other dtypes are refused, as is any other shape. Finite values outside
  ``[-1, 1]`` are clipped; NaN or inf is refused. A Python list (or tuple) of numbers is
  accepted when it converts to exactly the declared shape with a numeric dtype (a bool
  anywhere in it is refused). A ``torch.Tensor`` is accepted wherever a numpy array
  is (it is detached, so ``requires_grad`` is fine, and moved to the CPU where the
  backend computes on the host), under the same dtype and shape rule.
* **Seeds** are ``None`` or non-negative integers: a Python ``int`` or a numpy integer
  (``np.int64(3)`` seeds exactly as ``3``). Bools, floats, strings, generators and
  negative integers are refused.
* **Reset options** are ``None`` or a mapping whose entries are not read (the envs
  have no reset options; PettingZoo's API tests pass arbitrary entries); any other
  type is refused.

Every refusal is a :class:`ValueError` whose message states the rule and what was
given; nothing is converted silently (a complex action never loses its imaginary part,
a transposed array is never reshaped).
"""

from __future__ import annotations

import sys
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from swarm_envs.config import SwarmConfig, check_keywords, load_swarm_config
from swarm_envs.envs.common import NON_FINITE_ACTIONS, check_start_fits

#: dtype kinds an action may have: floating, signed and unsigned integers.
ACTION_KINDS = frozenset("fiu")

#: What an action must be (formatted with the declared shape).
ACTION_RULE = (
    "must be a real numeric array (float or integer dtype; not bool, complex, object or "
    "str) of shape {shape}"
)

#: What a seed must be.
SEED_RULE = (
    "seed must be None or a non-negative integer (a Python int or a numpy integer; "
    "not a bool, float, str or Generator)"
)


def check_seed(seed: Any) -> int | None:
    """``seed`` as a Python ``int`` (or ``None``) under the seed rule, else ValueError.

    >>> check_seed(np.int64(3)), check_seed(None)
    (3, None)
    >>> check_seed(-1)
    Traceback (most recent call last):
    ...
    ValueError: seed must be None or a non-negative integer ... got -1
    """
    if seed is None:
        return None
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise ValueError(f"{SEED_RULE}, got {_describe(seed)}")
    if seed < 0:
        raise ValueError(f"{SEED_RULE}, got {int(seed)}")
    return int(seed)


def check_reset_options(options: Any) -> None:
    """``reset(options=...)``: ``None`` or a mapping, whose entries are not read; else
    :class:`ValueError`.

    >>> check_reset_options({"options": 1})
    >>> check_reset_options(3)
    Traceback (most recent call last):
    ...
    ValueError: options must be None or a dict (its entries are not read: ...), got int
    """
    if options is not None and not isinstance(options, Mapping):
        raise ValueError(
            f"options must be None or a dict (its entries are not read: SwarmNav has no "
            f"reset options), got {type(options).__name__}"
        )


def is_tensor(value: Any) -> bool:
    """Whether ``value`` is a ``torch.Tensor`` (without importing torch)."""
    torch = sys.modules.get("torch")
    return torch is not None and isinstance(value, torch.Tensor)


def _describe(value: Any) -> str:
    """A short account of what was given, for an error message."""
    if value is None:
        return "None"
    if isinstance(value, np.ndarray):
        return f"a {value.dtype} array of shape {value.shape}"
    if is_tensor(value):
        return f"a {value.dtype} tensor of shape {tuple(value.shape)}"
    if isinstance(value, (np.generic, int, float, complex, str, bytes)):
        return f"{type(value).__name__} {value!r}"
    return f"a {type(value).__module__}.{type(value).__qualname__}".replace("builtins.", "")


def _refuse(name: str, shape: tuple[int, ...], given: str) -> ValueError:
    return ValueError(f"{name} {ACTION_RULE.format(shape=shape)}, got {given}")


def _holds_bool(value: Any) -> bool:
    """Whether a (nested) list or tuple holds a bool anywhere."""
    if isinstance(value, (bool, np.bool_)):
        return True
    if isinstance(value, (list, tuple)):
        return any(_holds_bool(v) for v in value)
    return False


def check_tensor_action(actions: Any, shape: tuple[int, ...], name: str = "actions") -> Any:
    """A ``torch.Tensor`` of a real dtype and exactly ``shape``, detached; else ValueError.

    It stays on its device (for the torch backend, which checks finiteness there).
    """
    import torch

    dt = actions.dtype
    if dt == torch.bool or dt.is_complex or not (dt.is_floating_point or _is_int_tensor(dt)):
        raise _refuse(name, shape, _describe(actions))
    if tuple(actions.shape) != shape:
        raise _refuse(name, shape, _describe(actions))
    return actions.detach()


def _is_int_tensor(dt: Any) -> bool:
    import torch

    return dt in (torch.uint8, torch.int8, torch.int16, torch.int32, torch.int64)


def as_action(actions: Any, shape: tuple[int, ...], name: str = "actions") -> np.ndarray:
    """``actions`` as a numpy array under the action rule, else :class:`ValueError`.

    A numpy array is returned as it is (no copy); a tensor is detached and copied to
    the host; a list or tuple is converted. Values are not checked here: every core
    refuses NaN/inf (:data:`~swarm_envs.envs.common.NON_FINITE_ACTIONS`) and clips the
    rest. ``O(1)`` for arrays and tensors of the right type.
    """
    if isinstance(actions, np.ndarray):
        a = actions
    elif is_tensor(actions):
        t = check_tensor_action(actions, shape, name)
        if t.dtype.is_floating_point and t.dtype.itemsize < 4:
            t = t.float()  # bfloat16 has no numpy dtype; float16 is exact in float32
        return t.cpu().numpy()
    elif isinstance(actions, (list, tuple)):
        try:
            a = np.asarray(actions)
        except (TypeError, ValueError):  # ragged or not numbers
            raise _refuse(name, shape, f"a {type(actions).__name__} that is no array") from None
        if a.dtype.kind in ACTION_KINDS and _holds_bool(actions):
            raise _refuse(name, shape, f"a {type(actions).__name__} holding a bool")
    else:
        raise _refuse(name, shape, _describe(actions))
    if a.dtype.kind not in ACTION_KINDS or a.shape != shape:
        raise _refuse(name, shape, _describe(a))
    return a


def make_config(
    config: str | None = None,
    overrides: Mapping[str, Any] | None = None,
    *,
    owner: str = "the SwarmNav env",
    keywords: Sequence[str] = ("config",),
) -> SwarmConfig:
    """Merge a YAML config (optional) and keyword overrides into a validated config.

    An override that is neither a :class:`SwarmConfig` field nor one of ``keywords``
    (the caller's own keyword arguments, named in the message with ``owner``) raises
    :class:`~swarm_envs.config.UnknownKeyError` (a ``TypeError`` and a ``ValueError``).
    Beyond the config's own checks, a Lagrangian start radius at which random starts
    cannot keep the bins apart is refused here
    (:func:`~swarm_envs.envs.common.check_start_fits`), so every env refuses it
    when built.
    """
    overrides = dict(overrides or {})
    check_keywords(overrides, owner, keywords)
    cfg = load_swarm_config(config, overrides)
    check_start_fits(cfg)
    return cfg


def check_agent_action(action: Any, dim: int, agent: str) -> np.ndarray:
    """One agent's action ``(dim,)`` under the action rule, finite; the error names it."""
    a = as_action(action, (dim,), f"action of {agent}")
    if not np.isfinite(a).all():
        raise ValueError(f"action of {agent}: {NON_FINITE_ACTIONS}")
    return a


def stack_agent_actions(actions: dict[str, Any], agents: Sequence[str], dim: int) -> np.ndarray:
    """Per-agent actions of shape ``(dim,)`` (PettingZoo) stacked into ``(N, dim)`` float64.

    Each agent's action follows the action rule; the error names the agent.
    """
    shape = (dim,)
    rows = [actions[a] for a in agents]
    # The usual case, numpy arrays of a real dtype and shape (dim,), checked without a
    # call per agent; anything else goes through as_action, whose error names the agent.
    stacked = None
    if all(type(r) is np.ndarray and r.dtype.kind in ACTION_KINDS for r in rows):
        try:
            stacked = np.array(rows, dtype=np.float64)
        except ValueError:  # rows of different shapes
            stacked = None
        if stacked is not None and stacked.shape != (len(rows), dim):
            stacked = None
    if stacked is None:
        rows = [as_action(r, shape, f"action of {a}") for a, r in zip(agents, rows, strict=True)]
        stacked = np.array(rows, dtype=np.float64)
    if not np.isfinite(stacked).all():
        bad = agents[int(np.flatnonzero(~np.isfinite(stacked).all(axis=1))[0])]
        raise ValueError(f"action of {bad}: {NON_FINITE_ACTIONS}")
    return stacked


__all__ = [
    "ACTION_KINDS",
    "ACTION_RULE",
    "SEED_RULE",
    "as_action",
    "check_agent_action",
    "check_reset_options",
    "check_seed",
    "check_tensor_action",
    "is_tensor",
    "make_config",
    "stack_agent_actions",
]
