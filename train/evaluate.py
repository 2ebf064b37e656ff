"""Evaluate policies on SwarmNav: the same seeded episodes for every policy, all at once.

A *policy* is anything with Stable-Baselines3's ``predict(obs, state=None,
episode_start=None, deterministic=True) -> (action, state)``: the analytic controllers
of :mod:`agents` and trained SB3 models alike. Two layouts are recognised from the
policy's ``observation_space`` / ``action_space`` (a policy without them is taken to be
per-agent, as the :mod:`agents` controllers are):

- ``"shared"``: one agent's observation ``(obs_dim,)`` → its action ``(d,)`` (parameter
  sharing; models trained on the SB3 ``VecEnv``). All B episodes × N agents are one
  batch: observations ``(B·N, obs_dim)`` → actions ``(B·N, d)``.
- ``"central"``: the whole swarm ``(N·obs_dim,)`` → ``(N·d,)`` (models trained on the
  Gymnasium env). Observations ``(B, N·obs_dim)`` → actions ``(B, N·d)``.

Anything else raises :class:`SpaceMismatchError`.

Episodes run on :class:`swarm_envs.envs.core.SwarmNavCore` with ``batch = episodes``:
every episode of a policy steps in one array call, and the start states come from
``numpy.random.default_rng(seed)``, so every policy sees the same starts (and a run is
reproducible). An episode ends as the environments end it: success (terminated) or
``max_steps`` of the config (truncated). Episodes that have ended keep being stepped with
the others but no longer count.

Measures per policy (means over episodes unless named otherwise; see
:data:`METRIC_DOCS` and ``docs/evaluation.md``): ``mean_return``, ``std_return``
(population std), ``success_rate``, ``mean_time_to_goal`` (simulated seconds, steps ×
dt, over the successful episodes; ``None`` when none succeeded),
``mean_episode_length`` (steps), ``collisions_per_episode`` (colliding pairs summed
over the episode's steps), ``control_effort`` (``Σ_t mean_i |a_i|²`` per episode, in
action units — the integral the reward's effort term penalises — then the mean over
episodes), ``control_effort_per_step`` (the same divided by the episode's length), and
the group statistics at the episode's last step: ``final_expanse``,
``final_polarization``, ``final_angular_momentum``, ``final_nearest_neighbor_distance``,
``final_centroid_distance``, ``final_fraction_arrived``.

Python API::

    from train.evaluate import evaluate_policies
    results = evaluate_policies({"potential": PotentialFieldController(cfg), "ppo": model},
                                cfg, episodes=20, seed=0, out_dir=None)

``out_dir`` also writes ``results.json``, ``summary.md``, ``curves.png`` and one GIF per
policy (:func:`write_outputs`). The console script is :mod:`train.cli_eval`.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from agents.base import swarm_config_of
from swarm_envs import ENV_ID
from swarm_envs.config import SwarmConfig, as_dict
from swarm_envs.envs.core import SwarmNavCore, observation_size

__all__ = [
    "CURVE_KEYS",
    "FINAL_KEYS",
    "METRIC_DOCS",
    "EpisodeBatch",
    "SpaceMismatchError",
    "evaluate_policies",
    "format_table",
    "load_sb3_model",
    "policy_mode",
    "run_episodes",
    "summarize",
    "write_outputs",
]

#: Statistics recorded at every step and plotted against time (mean over episodes).
CURVE_KEYS = ("centroid_distance", "expanse", "polarization", "angular_momentum")

#: Statistics reported at each episode's last step, as ``final_<key>``.
FINAL_KEYS = (
    "expanse",
    "polarization",
    "angular_momentum",
    "nearest_neighbor_distance",
    "centroid_distance",
    "fraction_arrived",
)

#: One line per reported measure (used for ``summary.md`` and the docs).
METRIC_DOCS = {
    "success_rate": "fraction of episodes that ended in success (terminated)",
    "mean_return": "mean over episodes of the summed cooperative reward",
    "std_return": "population standard deviation of the episode returns",
    "mean_time_to_goal": "simulated seconds (steps × dt) to success, over successful "
    "episodes; null when none succeeded",
    "mean_episode_length": "mean episode length in steps",
    "collisions_per_episode": "colliding pairs (closer than collision_radius) summed over "
    "the episode's steps, mean over episodes",
    "control_effort": "Σ_t mean_i |a_i|² over the episode (action units), mean over episodes",
    "control_effort_per_step": "the same divided by the episode length, mean over episodes",
    **{f"final_{k}": f"{k.replace('_', ' ')} at the episode's last step" for k in FINAL_KEYS},
}

#: Columns of the summary table: (key, header, format).
TABLE_COLUMNS = (
    ("success_rate", "success", "{:.0%}"),
    ("mean_return", "return (mean ± std)", "{:.2f}"),
    ("mean_time_to_goal", "time to goal (s)", "{:.1f}"),
    ("collisions_per_episode", "collisions / ep.", "{:.1f}"),
    ("control_effort", "control effort", "{:.1f}"),
    ("final_centroid_distance", "final centroid dist.", "{:.2f}"),
    ("final_expanse", "final expanse", "{:.2f}"),
    ("final_polarization", "final polarization", "{:.2f}"),
)


class SpaceMismatchError(ValueError):
    """A policy's observation/action spaces do not fit the environment."""


# --------------------------------------------------------------------------- policies


def policy_mode(policy: Any, cfg: SwarmConfig) -> str:
    """``"shared"`` or ``"central"``: how ``policy`` sees the swarm of ``cfg``.

    Read from ``policy.observation_space`` and ``policy.action_space`` (SB3 models and
    the :mod:`agents` controllers have them); a policy without them is ``"shared"``.

    Raises:
        SpaceMismatchError: the spaces fit neither the per-agent layout (``Box(-10, 10,
            (obs_dim,))`` → ``Box(-1, 1, (d,))``) nor the flat one (``(N·obs_dim,)`` →
            ``(N·d,)``).
    """
    obs_space = getattr(policy, "observation_space", None)
    act_space = getattr(policy, "action_space", None)
    if obs_space is None and act_space is None:
        return "shared"
    n, d, k = cfg.n_agents, cfg.dim, observation_size(cfg)
    layouts = {"shared": ((k,), (d,)), "central": ((n * k,), (n * d,))}
    obs_shape = getattr(obs_space, "shape", None)
    act_shape = getattr(act_space, "shape", None)
    expected = (
        f"the env's per-agent spaces (observation ({k},), action ({d},)) or its flat "
        f"spaces (observation ({n * k},), action ({n * d},)), both with actions in [-1, 1]"
    )
    found = (
        f"observation space {obs_space}, action space {act_space}"
        if obs_space is not None
        else f"action space {act_space}"
    )
    for mode, (o, a) in layouts.items():
        if tuple(obs_shape or ()) == o and tuple(act_shape or ()) == a:
            low = np.asarray(getattr(act_space, "low", -1.0), dtype=np.float64)
            high = np.asarray(getattr(act_space, "high", 1.0), dtype=np.float64)
            if not (np.allclose(low, -1.0) and np.allclose(high, 1.0)):
                break
            return mode
    raise SpaceMismatchError(f"{found}; expected {expected}")


def _detect_sb3_algorithm(data: Mapping[str, Any]) -> str:
    """Guess the SB3 algorithm of a saved model from its ``data`` JSON."""
    module = str(data.get("policy_class", {}).get("__module__", ""))
    for name in ("sac", "td3", "dqn", "ddpg"):
        if f".{name}." in module:
            return name.upper()
    return "PPO" if "clip_range" in data else "A2C"


def load_sb3_model(path: str | Path, device: str = "cpu") -> Any:
    """Load a Stable-Baselines3 model zip, detecting its algorithm.

    The algorithm is read from the zip's ``data`` JSON (the policy class's module and
    algorithm-specific keys), then PPO, SAC, A2C, TD3 and DQN are tried in turn.

    Raises:
        FileNotFoundError: no file at ``path``.
        ValueError: the file is not a model zip any of those algorithms can load.
    """
    import zipfile

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"model file not found: {p}")
    try:
        with zipfile.ZipFile(p) as zf:
            data = json.loads(zf.read("data"))
    except (zipfile.BadZipFile, KeyError, json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"{p} is not a Stable-Baselines3 model zip ({err})") from None
    import stable_baselines3 as sb3

    first = _detect_sb3_algorithm(data)
    order = [first] + [a for a in ("PPO", "SAC", "A2C", "TD3", "DQN") if a != first]
    errors = []
    for name in order:
        cls = getattr(sb3, name)
        try:
            return cls.load(p, device=device)
        except Exception as err:  # wrong algorithm: try the next one
            errors.append(f"{name}: {type(err).__name__}: {err}")
    raise ValueError(f"could not load {p} with any SB3 algorithm: " + "; ".join(errors))


# --------------------------------------------------------------------------- episodes


@dataclass
class EpisodeBatch:
    """Everything recorded for one policy over ``B`` episodes.

    Per-episode arrays are shaped ``(B,)``. ``curves`` maps each of :data:`CURVE_KEYS`
    to ``(T + 1, B)`` (index 0 is the start; an episode that has ended holds its last
    value); ``times`` is ``(T + 1,)`` in simulated seconds. ``trajectory`` holds episode
    0: positions and velocities ``(T0 + 1, N, d)`` and its goal ``(d,)``.
    """

    name: str
    mode: str
    dt: float
    returns: np.ndarray
    success: np.ndarray
    lengths: np.ndarray
    collisions: np.ndarray
    effort: np.ndarray
    final: dict[str, np.ndarray]
    curves: dict[str, np.ndarray]
    times: np.ndarray
    trajectory: dict[str, np.ndarray] = field(default_factory=dict)


def run_episodes(
    policy: Any,
    cfg: SwarmConfig | Any,
    episodes: int,
    seed: int,
    *,
    name: str = "policy",
    deterministic: bool = True,
    progress: bool = False,
    record_episode: bool = True,
) -> EpisodeBatch:
    """Run ``episodes`` seeded episodes of ``policy`` at once on one batched core.

    Args:
        policy: an object with SB3's ``predict``.
        cfg: a :class:`SwarmConfig` (or any env it can be read from).
        episodes: number of episodes ``B ≥ 1`` (all stepped together).
        seed: seed of the start states (``numpy.random.default_rng(seed)``).
        name: label of the progress bar and of the result.
        deterministic: passed to ``predict``.
        progress: show a tqdm progress bar (on stderr).
        record_episode: keep episode 0's trajectory (for the GIF).

    Raises:
        SpaceMismatchError: see :func:`policy_mode`.
        ValueError: ``episodes < 1``, or the policy returned non-finite actions.
    """
    cfg = swarm_config_of(cfg)
    if isinstance(episodes, bool) or int(episodes) != episodes or episodes < 1:
        raise ValueError(f"episodes must be an integer >= 1, got {episodes!r}")
    mode = policy_mode(policy, cfg)
    B, N, d = int(episodes), cfg.n_agents, cfg.dim
    core = SwarmNavCore(cfg, batch=B)
    core.reset(np.random.default_rng(seed))

    returns = np.zeros(B)
    lengths = np.zeros(B, np.int64)
    collisions = np.zeros(B)
    effort = np.zeros(B)
    success = np.zeros(B, bool)
    done = np.zeros(B, bool)
    stats = core.stats()
    final = {k: stats[k].astype(np.float64) for k in FINAL_KEYS}
    series = {k: [stats[k].astype(np.float64)] for k in CURVE_KEYS}
    xs, vs = [core.x[0].copy()], [core.v[0].copy()]
    goal0 = core.goal[0].copy()
    state: Any = None
    episode_start = np.ones(B, bool)

    from tqdm.auto import tqdm

    bar = tqdm(total=cfg.max_steps, desc=name, unit="step", disable=not progress, leave=True)
    try:
        for _ in range(cfg.max_steps):
            obs = core.observe()
            if mode == "central":
                action, state = policy.predict(
                    obs.reshape(B, -1),
                    state=state,
                    episode_start=episode_start,
                    deterministic=deterministic,
                )
            else:
                action, state = policy.predict(
                    obs.reshape(B * N, -1),
                    state=state,
                    episode_start=np.repeat(episode_start, N),
                    deterministic=deterministic,
                )
            episode_start = np.zeros(B, bool)
            a = np.asarray(action)
            if a.size != B * N * d:
                raise SpaceMismatchError(
                    f"policy {name!r} returned actions of shape {a.shape}; expected "
                    f"{(B * N, d) if mode == 'shared' else (B, N * d)}"
                )
            a = a.reshape(B, N, d)
            reward, terminated, truncated, stats = core.step(a)  # validates, clips
            clipped = np.clip(a.astype(np.float64), -1.0, 1.0)
            live = ~done
            returns[live] += reward[live]
            lengths[live] += 1
            collisions[live] += stats["collisions"][live]
            effort[live] += np.einsum("bik,bik->b", clipped, clipped)[live] / N
            for k in CURVE_KEYS:
                series[k].append(stats[k].astype(np.float64))
            ended = live & (terminated | truncated)
            success |= ended & terminated
            for k in FINAL_KEYS:
                final[k][ended] = stats[k][ended]
            if record_episode and live[0]:
                xs.append(core.x[0].copy())
                vs.append(core.v[0].copy())
            done |= ended
            bar.update(1)
            if progress:
                bar.set_postfix(
                    done=f"{int(done.sum())}/{B}", success=int(success.sum()), refresh=False
                )
            if done.all():
                break
    finally:
        bar.close()

    # Hold each episode's last value after it ended.
    steps = np.arange(len(series[CURVE_KEYS[0]]))
    hold = np.minimum(steps[:, None], lengths[None, :])
    curves = {k: np.take_along_axis(np.stack(v), hold, axis=0) for k, v in series.items()}
    trajectory = {}
    if record_episode:
        trajectory = {"x": np.stack(xs), "v": np.stack(vs), "goal": goal0}
    return EpisodeBatch(
        name=name,
        mode=mode,
        dt=cfg.dt,
        returns=returns,
        success=success,
        lengths=lengths,
        collisions=collisions,
        effort=effort,
        final=final,
        curves=curves,
        times=steps * cfg.dt,
        trajectory=trajectory,
    )


def summarize(batch: EpisodeBatch) -> dict[str, Any]:
    """The JSON-ready measures of one :class:`EpisodeBatch` (see :data:`METRIC_DOCS`)."""
    ok = batch.success
    lengths = batch.lengths.astype(np.float64)
    out: dict[str, Any] = {
        "mode": batch.mode,
        "mean_return": float(batch.returns.mean()),
        "std_return": float(batch.returns.std()),
        "success_rate": float(ok.mean()),
        "mean_time_to_goal": float(lengths[ok].mean() * batch.dt) if ok.any() else None,
        "mean_episode_length": float(lengths.mean()),
        "collisions_per_episode": float(batch.collisions.mean()),
        "control_effort": float(batch.effort.mean()),
        "control_effort_per_step": float((batch.effort / np.maximum(lengths, 1)).mean()),
    }
    for k in FINAL_KEYS:
        out[f"final_{k}"] = float(batch.final[k].mean())
    out["per_episode"] = {
        "return": [float(r) for r in batch.returns],
        "success": [bool(s) for s in ok],
        "steps": [int(n) for n in batch.lengths],
    }
    return out


def evaluate_policies(
    policies: Mapping[str, Any],
    cfg: SwarmConfig | Any,
    episodes: int = 20,
    seed: int = 0,
    *,
    out_dir: str | Path | None = None,
    env_id: str = ENV_ID,
    deterministic: bool = True,
    progress: bool = True,
    gif: bool = True,
    plots: bool = True,
    gif_size: int = 300,
    extra: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Evaluate every policy on the same ``episodes`` seeded episodes.

    Args:
        policies: ``{name: policy}``; each policy has SB3's ``predict``.
        cfg: the scenario, a :class:`SwarmConfig` or any swarm_envs env.
        episodes: episodes per policy.
        seed: seed of the start states, shared by all policies.
        out_dir: if given, write ``results.json``, ``summary.md``, ``curves.png`` and
            ``episode0_<name>.gif`` there (see :func:`write_outputs`).
        env_id: recorded in the results as ``"env"``.
        deterministic: passed to every ``predict``.
        progress: show a tqdm progress bar per policy.
        gif, plots: write the GIFs / the curves figure (with ``out_dir``).
        gif_size: GIF width and height in pixels.
        extra: more top-level entries for the results (e.g. the config path).

    Returns:
        ``{"env", "config", "episodes", "seed", "policies": {name: measures}}``, the
        content of ``results.json`` (JSON-ready; ``mean_time_to_goal`` may be None).

    Raises:
        SpaceMismatchError: a policy's spaces do not fit (checked for all before running).
    """
    cfg = swarm_config_of(cfg)
    if not policies:
        raise ValueError("no policies to evaluate")
    for name, policy in policies.items():
        try:
            policy_mode(policy, cfg)
        except SpaceMismatchError as err:
            raise SpaceMismatchError(f"policy {name!r}: {err}") from None
    batches = {
        name: run_episodes(
            policy,
            cfg,
            episodes,
            seed,
            name=name,
            deterministic=deterministic,
            progress=progress,
            record_episode=out_dir is not None and gif,
        )
        for name, policy in policies.items()
    }
    results: dict[str, Any] = {
        "env": env_id,
        **dict(extra or {}),
        "config": as_dict(cfg),
        "episodes": int(episodes),
        "seed": int(seed),
        "metrics": METRIC_DOCS,
        "policies": {name: summarize(b) for name, b in batches.items()},
    }
    if out_dir is not None:
        write_outputs(results, batches, cfg, out_dir, gif=gif, plots=plots, gif_size=gif_size)
    return results


# --------------------------------------------------------------------------- outputs


def _fmt(value: Any, spec: str) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    return spec.format(value)


def format_table(results: Mapping[str, Any]) -> str:
    """The policies' main measures as a markdown table (one row per policy)."""
    header = "| policy | " + " | ".join(h for _, h, _ in TABLE_COLUMNS) + " |"
    rule = "|---|" + "---:|" * len(TABLE_COLUMNS)
    rows = []
    for name, m in results["policies"].items():
        cells = []
        for key, _, spec in TABLE_COLUMNS:
            cell = _fmt(m.get(key), spec)
            if key == "mean_return" and m.get("std_return") is not None:
                cell += " ± " + _fmt(m["std_return"], spec)
            cells.append(cell)
        rows.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join([header, rule, *rows])


def _summary_markdown(results: Mapping[str, Any]) -> str:
    cfg = results["config"]
    lines = [
        f"# Evaluation: {results['env']}",
        "",
        f"{results['episodes']} episodes per policy, seed {results['seed']}, "
        f"N = {cfg['n_agents']}, dt = {cfg['dt']}, max_steps = {cfg['max_steps']}"
        + (f", config `{results['config_path']}`" if results.get("config_path") else "")
        + ".",
        "",
        format_table(results),
        "",
        "Measures (means over episodes):",
        "",
    ]
    shown = {k for k, _, _ in TABLE_COLUMNS} | {"std_return"}
    lines += [f"- `{k}`: {doc}" for k, doc in METRIC_DOCS.items() if k in shown]
    return "\n".join(lines) + "\n"


def _safe_name(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "policy"


def _plot_curves(batches: Mapping[str, EpisodeBatch], cfg: SwarmConfig, path: Path) -> Path:
    """Four panels (centroid distance, expanse, polarization, angular momentum) vs time."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    titles = {
        "centroid_distance": "centroid distance to goal",
        "expanse": "expanse",
        "polarization": "polarization (unit headings)",
        "angular_momentum": "angular momentum (unit headings)",
    }
    fig = Figure(figsize=(9.0, 6.5), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, 2, sharex=True).ravel()
    for ax, key in zip(axes, CURVE_KEYS, strict=True):
        for name, b in batches.items():
            c = b.curves[key]
            mean, std = c.mean(axis=1), c.std(axis=1)
            (line,) = ax.plot(b.times, mean, label=name, lw=1.6)
            ax.fill_between(b.times, mean - std, mean + std, color=line.get_color(), alpha=0.15)
        if key == "centroid_distance":
            ax.axhline(cfg.goal_radius, color="0.5", ls="--", lw=1, label="goal radius")
        ax.set_title(titles[key], fontsize=10)
        ax.grid(alpha=0.3)
    for ax in axes[2:]:
        ax.set_xlabel("time (s)")
    axes[0].legend(fontsize=8)
    episodes = next(iter(batches.values())).returns.size
    fig.suptitle(
        f"mean ± std over {episodes} episodes; an ended episode holds its last value, "
        "a curve stops when the policy's last episode ends",
        fontsize=10,
    )
    fig.savefig(path)
    return path


def _write_gif(batch: EpisodeBatch, cfg: SwarmConfig, path: Path, size: int) -> Path:
    """GIF of episode 0: at most ~100 frames of ``size``², trail of recent positions."""
    from swarm_envs.render import SwarmRenderer, write_gif

    xs, vs, goal = batch.trajectory["x"], batch.trajectory["v"], batch.trajectory["goal"]
    every = max(1, math.ceil(len(xs) / 100))
    renderer = SwarmRenderer(size=(size, size), trail_length=4 * every)
    frames = []
    for t in range(len(xs)):
        renderer.record(xs[t])
        if t % every == 0 or t == len(xs) - 1:
            frames.append(
                renderer.frame(xs[t], goal=goal, goal_radius=cfg.goal_radius, velocities=vs[t])
            )
    renderer.close()
    fps = min(25.0, 4.0 / (cfg.dt * every))  # about four times real time
    write_gif(frames, path, fps=fps, max_frames=None)
    if path.stat().st_size > 1_000_000:  # keep it small: halve the frames
        write_gif(frames[::2], path, fps=fps / 2, max_frames=None)
    return path


def write_outputs(
    results: Mapping[str, Any],
    batches: Mapping[str, EpisodeBatch],
    cfg: SwarmConfig,
    out_dir: str | Path,
    *,
    gif: bool = True,
    plots: bool = True,
    gif_size: int = 300,
) -> dict[str, Path]:
    """Write ``results.json``, ``summary.md``, ``curves.png`` and the GIFs; return paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {"results": out / "results.json", "summary": out / "summary.md"}
    paths["results"].write_text(
        json.dumps(results, indent=2, ensure_ascii=False) + "\n", encoding="utf-8"
    )
    paths["summary"].write_text(_summary_markdown(results), encoding="utf-8")
    if plots:
        paths["curves"] = _plot_curves(batches, cfg, out / "curves.png")
    if gif:
        for name, b in batches.items():
            if b.trajectory:
                key = f"gif_{name}"
                paths[key] = _write_gif(b, cfg, out / f"episode0_{_safe_name(name)}.gif", gif_size)
    return paths
