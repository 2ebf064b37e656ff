"""Training configuration: ``configs/train/*.yaml`` → a frozen, validated :class:`TrainConfig`.

Strict like the env configs: unknown keys, unknown SB3 hyperparameters and bad values
raise ``ValueError`` naming the key and what is allowed.

>>> tc = train_config_from_mapping({"algo": "PPO", "total_timesteps": 1000})
>>> tc.mode, tc.n_swarms
('shared', 8)
>>> train_config_from_mapping({"hyperparams": {"learning_rat": 1e-3}})
Traceback (most recent call last):
...
ValueError: hyperparams.learning_rat is not a PPO argument; allowed: ...
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Mapping
from dataclasses import Field, dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import yaml

from swarm_envs import ENV_ID
from swarm_envs.config import (
    SwarmConfig,
    config_from_mapping,
    load_swarm_config,
    resolve_config_path,
)
from train.es import ES
from train.hyperparams import check_hyperparams
from train.integers import ACCEPTED, check_integer, coerce_integer_fields, integral

if TYPE_CHECKING:
    from stable_baselines3.common.base_class import BaseAlgorithm

#: ``PPO`` and ``SAC`` are SB3's; ``ES`` is evolution strategies on the deterministic
#: shared policy (:mod:`train.es`).
ALGOS = ("PPO", "SAC", ES)
#: The SB3 policy every run builds (its class per algorithm: ``policy_aliases``).
POLICY = "MlpPolicy"
#: Keys a resumed run may change (``swarm-train --resume DIR key=value``): the total
#: (to extend a run) and the checkpoint cadence; none of them changes what is learned.
RESUME_KEYS = ("total_timesteps", "checkpoint_freq", "checkpoint_seconds", "checkpoint_keep")
#: Largest seed numpy's seeding accepts.
MAX_SEED = 2**32 - 1
MODES = ("shared", "central")

#: What a residual policy corrects (``TrainConfig.residual_corrects``).
RESIDUAL_CORRECTS = ("action", "gains")

#: torch CPU threads of training and evaluation unless a config or flag says otherwise.
DEFAULT_TORCH_THREADS = 1
#: SB3 constructor arguments that the trainer sets itself (not allowed in ``hyperparams``).
RESERVED = {"policy", "env", "seed", "device", "policy_kwargs", "tensorboard_log", "verbose"}


def algorithm_class(name: str) -> type[BaseAlgorithm]:
    """The SB3 class for ``name`` (one of :data:`ALGOS`; ``ES`` saves its policy as a
    PPO model, so its class is PPO's)."""
    import stable_baselines3

    if name not in ALGOS:
        raise ValueError(f"algo must be one of {ALGOS}, got {name!r}")
    return getattr(stable_baselines3, "PPO" if name == ES else name)


def actor_critic(cls: type[BaseAlgorithm]) -> bool:
    """Whether ``cls``'s :data:`POLICY` is an actor-critic policy (PPO's: one actor and
    one value function, what :class:`train.residual.CriticWarmup` warms up), not SAC's
    actor with Q-functions."""
    from stable_baselines3.common.policies import ActorCriticPolicy

    policy = cls.policy_aliases.get(POLICY)
    return isinstance(policy, type) and issubclass(policy, ActorCriticPolicy)


class RunConfig:
    """What every training run's config shares (SB3's and RLlib's): the env part
    (``env_config`` YAML plus ``env`` overrides), ``net_arch`` and ``hyperparams``.

    A mixin for the frozen dataclasses that declare those fields.
    """

    __dataclass_fields__: ClassVar[dict[str, Field[Any]]]  # the subclasses are dataclasses
    env_config: str | None  # declared by the subclasses' dataclass fields
    env: Mapping[str, Any]
    net_arch: Any
    hyperparams: Mapping[str, Any]

    def swarm_config(self) -> SwarmConfig:
        """The env configuration this run trains on (YAML, then the ``env`` overrides)."""
        return load_swarm_config(self.env_config, dict(self.env))

    def _check_env(self) -> None:
        try:
            self.swarm_config()
        except ValueError as err:
            raise ValueError(f"env: {err}") from None
        except yaml.YAMLError as err:
            raise ValueError(f"env_config: {yaml_text_error(err)}") from None
        except OSError as err:
            raise ValueError(f"env_config: cannot read {err.filename}: {err.strerror}") from None

    def to_dict(self) -> dict[str, Any]:
        """Plain data for YAML (saved beside the model or checkpoint)."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["net_arch"] = list(self.net_arch)
        if hasattr(self, "plugins"):
            out["plugins"] = list(self.plugins)
        out["env"] = dict(self.env)
        out["hyperparams"] = dict(self.hyperparams)
        return out


@dataclass(frozen=True)
class TrainConfig(RunConfig):
    """One training run. ``total_timesteps`` counts SB3 timesteps: agent-steps in
    ``shared`` mode (each vector step is ``n_swarms × n_agents`` of them), swarm-steps in
    ``central`` mode."""

    algo: str = "PPO"
    """``PPO`` or ``SAC`` (SB3's), or ``ES``: evolution strategies on the deterministic
    shared policy (:mod:`train.es`; ``n_swarms`` is the episodes each candidate runs)."""
    mode: str = "shared"
    """``shared``: one policy for every agent through ``swarm_nav_v0.vec_env``;
    ``central``: one policy over the whole swarm through the Gymnasium env."""
    env_id: str = ENV_ID
    """Gymnasium id (central mode) and the name recorded in results."""
    env_config: str | None = None
    """Path of an env YAML (``configs/env/...``), or null for the defaults."""
    env: dict = field(default_factory=dict)
    """Overrides of :class:`swarm_envs.config.SwarmConfig` keys (e.g. ``n_agents``)."""
    plugins: tuple[str, ...] = ()
    """Python files or module names imported before the env config is read: a user's
    own tasks and models (:mod:`swarm_envs.plugins`). A relative file path is read from
    the working folder, else from the train config's folder."""
    n_swarms: int = 8
    """Parallel swarms (shared mode: batch of the VecEnv; central: number of envs)."""
    total_timesteps: int = 100_000
    """SB3 timesteps to train for (see the class docstring)."""
    seed: int = 0
    """Seed of the model, the training envs and SB3's global seeding."""
    net_arch: tuple[int, ...] = (64, 64)
    """Hidden layer sizes of the policy and value networks."""
    encoder: str | None = None
    """Shared mode, PPO or SAC: ``deepsets`` reads the neighbour slots as a set
    (:class:`train.encoders.NeighborSetEncoder`: one network over every slot, pooled by
    mean and maximum over the real neighbours, beside the agent's own features) before
    ``net_arch``; ``null``: the flat observation."""
    encoder_width: int = 32
    """With ``encoder``: the width of its per-slot network and of each pooled code."""
    hyperparams: dict = field(default_factory=dict)
    """Extra SB3 constructor arguments, checked against the algorithm's signature."""
    residual: str | None = None
    """Shared mode: the name of a baseline (``pd``, ``follow``, ... of
    :data:`agents.CONTROLLERS`) whose action the policy corrects, ``a = clip(b(o) +
    r_θ(o), −1, 1)`` (:mod:`train.residual`); the baseline's gains are the tuned ones at
    the start of training, and are recorded in the model. ``null``: the policy acts alone."""
    residual_log_std: float = -1.0
    """With ``residual``: the initial log standard deviation of the policy's Gaussian
    (the exploration noise around the baseline's action, before ``residual_scale``;
    SB3's default is 0)."""
    residual_scale: float = 1.0
    """With ``residual``: the scale ``c`` in (0, 1] of the correction, ``a = clip(b(o) +
    c · r_θ(o), −1, 1)``: the policy stays within ``c`` of the baseline's action on every
    axis, in training and at evaluation (recorded in the model)."""
    residual_warmup: int = 0
    """With ``residual``: timesteps at the start during which only the value function
    learns (:class:`train.residual.CriticWarmup`); the policy stays the baseline's. An
    actor-critic algorithm's (PPO); refused with SAC, whose critics are Q-functions."""
    residual_corrects: str = "action"
    """With ``residual``: what the policy corrects. ``action``: the baseline's action
    (above); ``gains``: the baseline's gains, per agent, by a learned linear schedule of
    a few features of its observation (:mod:`train.gain_schedule`; ``algo: ES``, a
    baseline with a schedule, ``residual_scale`` 1)."""
    eval_freq: int = 0
    """Evaluate against the analytic controller every this many timesteps (0 = never)."""
    eval_episodes: int = 10
    """Episodes per periodic evaluation."""
    eval_seed: int = 1_000_000
    """Seed of the evaluation episodes (kept apart from the training seed)."""
    checkpoint_freq: int = 0
    """Also save a checkpoint every this many timesteps (0 = by wall time only)."""
    checkpoint_seconds: float = 120.0
    """Save a checkpoint every this many seconds of wall time (0 = by timesteps only).
    Checkpoints are taken between updates; a run killed outright loses at most this much
    wall time plus one rollout and update."""
    checkpoint_keep: int = 3
    """How many of the latest checkpoints ``checkpoints/`` keeps (older ones are removed)."""
    device: str = "cpu"
    """Torch device for the networks."""
    torch_threads: int | None = DEFAULT_TORCH_THREADS
    """``torch.set_num_threads`` for the run and its evaluations; null leaves torch's
    own choice (one per core). One thread is the default: with small networks
    (``64 × 64``) a second thread gains little, while on cores shared with the env step
    or other work each minibatch waits for the slowest thread."""

    def __post_init__(self) -> None:
        cls = algorithm_class(self.algo)
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {self.mode!r}")
        for name, low in (
            ("n_swarms", 1),
            ("total_timesteps", 1),
            ("seed", 0),
            ("eval_freq", 0),
            ("eval_episodes", 1),
            ("eval_seed", 0),
            ("checkpoint_freq", 0),
            ("checkpoint_keep", 1),
            ("residual_warmup", 0),
            ("encoder_width", 1),
        ):
            object.__setattr__(self, name, check_integer(name, getattr(self, name), low=low))
        for name in ("seed", "eval_seed"):
            if getattr(self, name) > MAX_SEED:
                raise ValueError(
                    f"{name} must be an integer in [0, {MAX_SEED}], got {getattr(self, name)!r}"
                )
        seconds = self.checkpoint_seconds
        if (
            isinstance(seconds, bool)
            or not isinstance(seconds, (int, float))
            or not math.isfinite(seconds)
            or seconds < 0
        ):
            raise ValueError(
                f"checkpoint_seconds must be a number >= 0 (0 = by timesteps only), got {seconds!r}"
            )
        object.__setattr__(self, "checkpoint_seconds", float(seconds))
        problem = device_problem(self.device)
        if problem is not None:
            raise ValueError(f"device {problem}")
        if self.torch_threads is not None:
            threads = integral(self.torch_threads)
            if threads is None or threads < 1:
                raise ValueError(
                    f"torch_threads must be null or an integer >= 1 ({ACCEPTED}), "
                    f"got {self.torch_threads!r}"
                )
            object.__setattr__(self, "torch_threads", threads)
        object.__setattr__(self, "net_arch", net_arch_tuple(self.net_arch))
        object.__setattr__(self, "env", env_overrides(self.env))
        object.__setattr__(self, "plugins", load_run_plugins(self.plugins))
        if not isinstance(self.hyperparams, Mapping):
            raise ValueError(f"hyperparams must be a mapping, got {self.hyperparams!r}")
        if self.algo == ES:
            self._check_es_only()
        else:
            self._check_sb3_keywords(cls)
        self._check_encoder()
        if self.residual is not None:
            from train.residual import check_baseline_name

            if self.mode != "shared":
                raise ValueError(f"residual needs mode 'shared', got mode {self.mode!r}")
            check_baseline_name(self.residual)
        if self.residual_warmup > 0 and not actor_critic(cls):
            raise ValueError(
                f"residual_warmup = {self.residual_warmup} trains the value function alone "
                f"first, which needs an actor-critic policy (algo PPO); algo {self.algo!r} "
                "has none: set residual_warmup to 0 or algo to PPO"
            )
        if isinstance(self.residual_log_std, bool) or not isinstance(
            self.residual_log_std, int | float
        ):
            raise ValueError(f"residual_log_std must be a number, got {self.residual_log_std!r}")
        from train.residual import check_residual_scale

        object.__setattr__(self, "residual_scale", check_residual_scale(self.residual_scale))
        if self.residual is None and self.residual_scale != 1.0:
            raise ValueError(
                f"residual_scale = {self.residual_scale} scales a residual policy's "
                "correction; set residual to a baseline or leave residual_scale at 1"
            )
        self._check_residual_corrects()
        self._check_env()  # a typo in the env part fails before any training starts
        if self.algo == ES:
            from train.es import check_es_hyperparams

            hyper = check_es_hyperparams(self.hyperparams)
        else:
            n_envs = self.n_slots
            hyper = check_hyperparams(self.algo, self.hyperparams, n_envs)
        object.__setattr__(self, "hyperparams", hyper)

    def _check_sb3_keywords(self, cls: type[BaseAlgorithm]) -> None:
        """Every key of ``hyperparams`` is an argument of the SB3 class ``cls``."""
        allowed = set(inspect.signature(cls.__init__).parameters) - RESERVED - {"self"}
        allowed = {a for a in allowed if not a.startswith("_")}
        for key in self.hyperparams:
            if key not in allowed:
                raise ValueError(
                    f"hyperparams.{key} is not a {self.algo} argument; "
                    f"allowed: {', '.join(sorted(allowed))}"
                )

    def _check_residual_corrects(self) -> None:
        """``residual_corrects`` is one of :data:`RESIDUAL_CORRECTS`; ``gains`` needs a
        ``residual`` with a gain schedule, ``algo: ES`` and ``residual_scale`` 1."""
        if self.residual_corrects not in RESIDUAL_CORRECTS:
            raise ValueError(
                f"residual_corrects must be one of {', '.join(RESIDUAL_CORRECTS)}, "
                f"got {self.residual_corrects!r}"
            )
        if self.residual_corrects == "action":
            return
        if self.residual is None:
            raise ValueError(
                "residual_corrects: gains schedules a baseline's gains; name the baseline "
                "in residual"
            )
        if self.algo != ES:
            raise ValueError(
                f"residual_corrects: gains is trained by evolution strategies (algo ES), "
                f"got algo {self.algo!r}"
            )
        if self.residual_scale != 1.0:
            raise ValueError(
                f"residual_scale = {self.residual_scale} scales an action correction; a "
                "gain schedule has none: leave residual_scale at 1"
            )
        from train.gain_schedule import schedule_of

        schedule_of(self.residual)

    def _check_encoder(self) -> None:
        """``encoder`` is null or one of :data:`train.encoders.ENCODERS`, with a shared
        SB3 policy (ES's network is the flat actor; central mode sees every agent at
        once)."""
        from train.encoders import ENCODERS

        if self.encoder is None:
            return
        if self.encoder not in ENCODERS:
            raise ValueError(
                f"encoder must be null or one of {', '.join(ENCODERS)}, got {self.encoder!r}"
            )
        if self.mode != "shared":
            raise ValueError(
                f"encoder {self.encoder!r} reads one agent's neighbour slots: it needs mode "
                f"'shared', got mode {self.mode!r}"
            )
        if self.algo == ES:
            raise ValueError(
                f"encoder {self.encoder!r} is an SB3 features extractor: algo ES trains the "
                "flat actor only; set encoder to null or algo to PPO or SAC"
            )

    def _check_es_only(self) -> None:
        """What an ``algo: ES`` run (:mod:`train.es`) refuses: central mode, a periodic
        evaluation, a value-function warm-up."""
        if self.mode != "shared":
            raise ValueError(
                f"algo ES trains a shared policy: mode must be 'shared', got {self.mode!r}"
            )
        for name in ("residual_warmup", "eval_freq"):
            if getattr(self, name):
                raise ValueError(
                    f"{name} must be 0 with algo ES (it has no value function and reports its "
                    f"centre's return every generation), got {getattr(self, name)!r}"
                )

    @property
    def n_slots(self) -> int:
        """Env slots SB3 sees: ``n_swarms × n_agents`` (shared) or ``n_swarms`` (central)."""
        return self.n_swarms * (self.swarm_config().n_agents if self.mode == "shared" else 1)


def load_run_plugins(plugins: Any, base: str | Path | None = None) -> tuple[str, ...]:
    """Import each plugin of ``plugins`` (a list of files or module names;
    :func:`~swarm_envs.plugins.load_plugin`) and return them as a tuple, a file found
    relative to ``base`` (a train config's folder) as its absolute path.

    Raises:
        ValueError: ``plugins`` is not a list of strings, or a plugin cannot be loaded
            (naming it).
    """
    from swarm_envs.plugins import load_plugin

    if isinstance(plugins, str) or not isinstance(plugins, (list, tuple)):
        raise ValueError(f"plugins must be a list of .py files or module names, got {plugins!r}")
    out = []
    for ref in plugins:
        if not isinstance(ref, str):
            raise ValueError(f"plugins must be a list of .py files or module names, got {ref!r}")
        module = load_plugin(ref, base)
        path = getattr(module, "__file__", None)
        if base is not None and path is not None and not Path(ref).is_file():
            out.append(str(Path(path).resolve()))  # found relative to base
        else:
            out.append(ref)
    return tuple(out)


def net_arch_tuple(net_arch: Any) -> tuple[int, ...]:
    """``net_arch`` as a tuple of layer sizes (integral numbers such as ``6.4e1`` too).

    Raises:
        ValueError: not a non-empty list of integers >= 1.
    """
    problem = ValueError(f"net_arch must be a non-empty list of integers >= 1, got {net_arch!r}")
    if isinstance(net_arch, (str, bytes, Mapping)) or not hasattr(net_arch, "__iter__"):
        raise problem
    sizes = tuple(integral(h) for h in net_arch)
    layers = tuple(h for h in sizes if h is not None and h >= 1)
    if not sizes or len(layers) != len(sizes):
        raise problem
    return layers


def env_overrides(env: Any) -> dict[str, Any]:
    """The ``env`` section with integral values of integer keys as ``int``
    (``max_steps: 1e3`` → ``1000``; :func:`train.integers.coerce_integer_fields`).

    Raises:
        ValueError: ``env`` is not a mapping.
    """
    if not isinstance(env, Mapping):
        raise ValueError(f"env must be a mapping of SwarmConfig keys, got {env!r}")
    return coerce_integer_fields(SwarmConfig, env)


def device_problem(device: Any) -> str | None:
    """Why ``device`` cannot run the networks here, or None when it can.

    Allowed: ``auto``, ``cpu``, and ``cuda``/``cuda:<index>`` or ``mps`` where present.
    """
    import torch

    if not isinstance(device, str):
        return f"must be a torch device name ('cpu', 'cuda', 'cuda:0', 'auto'), got {device!r}"
    if device == "auto":
        return None
    try:
        dev = torch.device(device)
    except (RuntimeError, ValueError):
        return f"must be a torch device name ('cpu', 'cuda', 'cuda:0', 'auto'), got {device!r}"
    if dev.type == "cpu":
        return None
    if dev.type == "cuda":
        count = torch.cuda.device_count() if torch.cuda.is_available() else 0
        if count == 0:
            return f"{device!r} is not available: this machine has no CUDA device (use cpu)"
        if dev.index is not None and dev.index >= count:
            return f"{device!r} is not available: this machine has {count} CUDA device(s)"
        return None
    if dev.type == "mps" and torch.backends.mps.is_available():
        return None
    return f"{device!r} is not available here (use cpu, auto or cuda)"


def train_config_from_mapping(data: Mapping[str, Any]) -> TrainConfig:
    """Build a :class:`TrainConfig` strictly (unknown keys name themselves)."""
    return config_from_mapping(TrainConfig, data)


def yaml_text_error(err: yaml.YAMLError, source: str | Path | None = None) -> str:
    """A YAML syntax error in one line: ``<file>: invalid YAML at line L, column C: ...``."""
    from train.cli_common import yaml_message

    return yaml_message(err, None if source is None else str(source))


def read_yaml_mapping(path: str | Path, kind: str = "config") -> dict[str, Any]:
    """The mapping at the top of the YAML file ``path`` (empty file: ``{}``).

    Unreadable files, YAML syntax errors and non-mappings raise ``ValueError`` naming
    the file (and the line and column of a syntax error).
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise ValueError(f"{kind} {p} is not UTF-8 text") from None
    except OSError as err:
        raise ValueError(f"cannot read {kind} {p}: {err.strerror}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise ValueError(f"{kind} {yaml_text_error(err, p)}") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ValueError(f"{kind} {p} must hold a mapping, got {type(data).__name__}")
    return data


def parse_overrides(items: list[str]) -> dict[str, Any]:
    """``["total_timesteps=5000", "env.n_agents=4"]`` → nested dict; values parsed as YAML."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key or any(not part for part in key.split(".")):
            raise ValueError(f"override {item!r} must look like key=value (e.g. seed=3)")
        try:
            value = yaml.safe_load(raw)
        except yaml.YAMLError as err:
            raise ValueError(f"override {item!r}: {yaml_text_error(err)}") from None
        parts = key.split(".")
        node = out
        for part in parts[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ValueError(f"override {item!r} conflicts with another override")
        node[parts[-1]] = value
    return out


def load_train_config(
    path: str | Path | None,
    overrides: Mapping[str, Any] | None = None,
    plugins: tuple[str, ...] = (),
) -> TrainConfig:
    """Load ``configs/train/<name>.yaml`` and merge ``overrides`` (nested dicts merge).

    ``plugins`` (files or module names, ``swarm-train --plugin``) are loaded first and
    added to the file's ``plugins``, whose relative paths may be relative to the file.
    """
    data: dict[str, Any] = {}
    head = load_run_plugins(list(plugins))
    if path is not None:
        found = resolve_config_path(path, "train", "train config")
        data = read_yaml_mapping(found, "train config")
        if "plugins" in data:
            data["plugins"] = load_run_plugins(data["plugins"], found.parent)
    if head:
        data["plugins"] = (*head, *[p for p in data.get("plugins", ()) if p not in head])
    return train_config_from_mapping(merge_overrides(data, overrides))


def merge_overrides(data: Mapping[str, Any], overrides: Mapping[str, Any] | None) -> dict:
    """``data`` with ``overrides`` on top (a mapping merges into a mapping section)."""
    out = dict(data)
    for key, value in (overrides or {}).items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = {**out[key], **value}
        else:
            out[key] = value
    return out


def resume_config(saved: TrainConfig, overrides: Mapping[str, Any] | None) -> TrainConfig:
    """The config of a resumed run: ``saved`` with only :data:`RESUME_KEYS` overridden.

    An override that changes any other key raises ``ValueError`` naming it; one that
    repeats the saved value is accepted.
    """
    tc = train_config_from_mapping(merge_overrides(saved.to_dict(), overrides))
    changed = [
        f"{key} ({getattr(saved, key)!r} -> {getattr(tc, key)!r})"
        for key in (f.name for f in fields(TrainConfig))
        if key not in RESUME_KEYS and getattr(tc, key) != getattr(saved, key)
    ]
    if changed:
        raise ValueError(
            "--resume continues the run with its saved config; cannot change "
            f"{', '.join(changed)}; only {', '.join(RESUME_KEYS)} may be given"
        )
    return tc
