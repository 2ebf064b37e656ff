"""Validation of the SB3 hyperparameters a training config may set (``hyperparams``).

Every argument of PPO and SAC that a YAML config can express has a rule here: its type
and its allowed range, checked when the config is loaded, before anything is trained or
written. Arguments that take Python objects (buffer classes, action noise, their
keyword dictionaries) cannot come from YAML and are refused.

Numbers written as YAML strings such as ``1e-3`` (PyYAML reads exponents without a
decimal point as text) are accepted where a real number is expected and stored as
floats; integral numbers such as ``2e3``, ``2_048`` or ``2048.0`` are accepted where an
integer is expected and stored as integers.

>>> check_hyperparams("PPO", {"learning_rate": "1e-3", "n_steps": 64}, n_envs=8)
{'learning_rate': 0.001, 'n_steps': 64}
>>> check_hyperparams("PPO", {"gamma": 1.5}, n_envs=8)
Traceback (most recent call last):
...
ValueError: hyperparams.gamma must be a number in (0, 1], got 1.5
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from typing import Any

from train.integers import integral

#: Arguments that need Python objects, which a YAML config cannot build.
OBJECT_ARGS = frozenset(
    {
        "rollout_buffer_class",
        "rollout_buffer_kwargs",
        "replay_buffer_class",
        "replay_buffer_kwargs",
        "action_noise",
    }
)

_NUMBER = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")

Check = Callable[[str, Any], Any]


def _real(value: Any) -> float | None:
    """``value`` as a finite float, or None when it is no real number."""
    if isinstance(value, bool):
        return None
    if isinstance(value, str) and _NUMBER.fullmatch(value.strip()):
        value = float(value)
    if isinstance(value, (int, float)) and math.isfinite(value):
        return float(value)
    return None


def real(low: float, high: float = math.inf, *, low_open: bool, high_open: bool = True) -> Check:
    """A real number in the interval from ``low`` to ``high``."""
    left, right = "(" if low_open else "[", ")" if high_open or high == math.inf else "]"
    allowed = f"a number in {left}{low:g}, {'inf' if high == math.inf else f'{high:g}'}{right}"

    def check(key: str, value: Any) -> float:
        x = _real(value)
        if x is None or x < low or (low_open and x == low) or x > high or (high_open and x == high):
            raise ValueError(f"hyperparams.{key} must be {allowed}, got {value!r}")
        return x

    return check


def integer(low: int, *, extra: tuple[int, ...] = ()) -> Check:
    """An integer ``>= low`` (or one of ``extra``)."""
    allowed = f"an integer >= {low}" + "".join(f" or {e}" for e in extra)

    def check(key: str, value: Any) -> int:
        n = integral(value)
        if n is None or (n < low and n not in extra):
            raise ValueError(f"hyperparams.{key} must be {allowed}, got {value!r}")
        return n

    return check


def boolean(key: str, value: Any) -> bool:
    """true or false."""
    if not isinstance(value, bool):
        raise ValueError(f"hyperparams.{key} must be true or false, got {value!r}")
    return value


def optional(inner: Check) -> Check:
    """null, or what ``inner`` allows."""

    def check(key: str, value: Any) -> Any:
        if value is None:
            return None
        try:
            return inner(key, value)
        except ValueError as err:
            raise ValueError(f"{err} (or null)") from None

    return check


def auto_or_positive(key: str, value: Any) -> Any:
    """SAC's ``ent_coef``: ``auto``, ``auto_<start value>`` or a number > 0."""
    if isinstance(value, str) and (value == "auto" or value.startswith("auto_")):
        start = value[5:]
        if value == "auto" or ((x := _real(start)) is not None and x > 0):
            return value
    x = _real(value)
    if x is None or x <= 0:
        raise ValueError(
            f"hyperparams.{key} must be 'auto', 'auto_<number > 0>' or a number > 0, got {value!r}"
        )
    return x


def auto_or_real(key: str, value: Any) -> Any:
    """SAC's ``target_entropy``: ``auto`` or a number."""
    if value == "auto":
        return value
    x = _real(value)
    if x is None:
        raise ValueError(f"hyperparams.{key} must be 'auto' or a number, got {value!r}")
    return x


def train_freq(key: str, value: Any) -> Any:
    """SAC's ``train_freq``: an integer >= 1 (vector steps) or ``[n, "step"]``."""
    if isinstance(value, (list, tuple)) and len(value) == 2:
        n, unit = integral(value[0]), value[1]
        if n is not None and n >= 1 and unit == "step":
            return [n, unit]
        if unit == "episode":
            raise ValueError(
                f"hyperparams.{key}: unit 'episode' needs a single env; training runs "
                "several (use an integer: vector steps)"
            )
    elif (n := integral(value)) is not None and n >= 1:
        return n
    raise ValueError(f"hyperparams.{key} must be an integer >= 1 or [n, 'step'], got {value!r}")


_COMMON: dict[str, Check] = {
    "learning_rate": real(0.0, low_open=True),
    "gamma": real(0.0, 1.0, low_open=True, high_open=False),
    "use_sde": boolean,
    "sde_sample_freq": integer(1, extra=(-1,)),
    "stats_window_size": integer(1),
}

RULES: dict[str, dict[str, Check]] = {
    "PPO": {
        **_COMMON,
        "n_steps": integer(1),
        "batch_size": integer(1),
        "n_epochs": integer(1),
        "gae_lambda": real(0.0, 1.0, low_open=False, high_open=False),
        "clip_range": real(0.0, low_open=True),
        "clip_range_vf": optional(real(0.0, low_open=True)),
        "normalize_advantage": boolean,
        "ent_coef": real(0.0, low_open=False),
        "vf_coef": real(0.0, low_open=False),
        "max_grad_norm": real(0.0, low_open=True),
        "target_kl": optional(real(0.0, low_open=True)),
    },
    "SAC": {
        **_COMMON,
        "buffer_size": integer(1),
        "learning_starts": integer(0),
        "batch_size": integer(1),
        "tau": real(0.0, 1.0, low_open=True, high_open=False),
        "train_freq": train_freq,
        "gradient_steps": integer(1, extra=(-1,)),
        "optimize_memory_usage": boolean,
        "n_steps": integer(1),
        "ent_coef": auto_or_positive,
        "target_update_interval": integer(1),
        "target_entropy": auto_or_real,
        "use_sde_at_warmup": boolean,
    },
}


def check_hyperparams(algo: str, hyperparams: Mapping[str, Any], n_envs: int) -> dict[str, Any]:
    """Validate ``hyperparams`` of ``algo`` for a run on ``n_envs`` env slots.

    Returns them with numbers normalised (numeric strings as floats). Raises
    ``ValueError`` naming the first bad key and what it allows. Keys that are not
    arguments of ``algo`` are the caller's check (:class:`train.config.TrainConfig`).
    """
    rules = RULES[algo]
    out: dict[str, Any] = {}
    for key, value in hyperparams.items():
        if key in OBJECT_ARGS:
            raise ValueError(
                f"hyperparams.{key} takes a Python object, which a config cannot give; remove it"
            )
        rule = rules.get(key)
        out[key] = rule(key, value) if rule is not None else value
    if algo == "PPO":
        n_steps = out.get("n_steps", 2048)
        if n_steps * n_envs < 2:
            raise ValueError(
                f"hyperparams.n_steps × env slots must be > 1 (PPO normalises advantages "
                f"over a rollout), got {n_steps} × {n_envs}"
            )
        if out.get("normalize_advantage", True) and out.get("batch_size", 64) < 2:
            raise ValueError(
                "hyperparams.batch_size must be >= 2 when normalize_advantage is true "
                f"(the default), got {out['batch_size']}"
            )
    return out
