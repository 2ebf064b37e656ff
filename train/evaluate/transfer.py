"""Size transfer: every policy, unchanged, on swarms of several sizes ``N``.

:func:`evaluate_transfer` runs each policy on the same seeded episodes
(:func:`~train.evaluate.episodes.run_episodes`) at every size of a list, the config
otherwise unchanged (``dataclasses.replace(cfg, n_agents=N)``), and measures each
``(policy, N)`` with :func:`~train.evaluate.measures.summarize`. Each size runs on the
backend its config picks (``backend``, ``device``; ``"auto"`` chooses by size, see
:func:`swarm_envs.envs.backends.select_backend`), recorded per size.

Only a *shared* policy transfers: it maps one agent's observation ``(obs_dim,)`` to
its action, and ``obs_dim`` does not depend on ``N`` (the ``n_neighbors`` nearest,
padded). A *central* policy (a model trained on the Gymnasium env) reads the whole
swarm as one ``(N·obs_dim,)`` vector, so it fits one ``N`` only: it is refused with
:class:`CentralPolicyError`.

Outputs (:func:`write_transfer_outputs`): ``results.json`` (no NaN or infinity; an
undefined measure is ``null``), ``summary.md`` (the table of :func:`format_transfer_table`),
``transfer.csv`` (one row per policy and size; an undefined measure is an empty cell)
and ``transfer.png`` (success rate, return, time to goal and collisions against ``N``,
one line per policy; see :func:`~train.evaluate.figures.plot_transfer`).
"""

from __future__ import annotations

import csv
import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from agents.base import swarm_config_of
from swarm_envs import ENV_ID
from swarm_envs.config import SwarmConfig, as_dict
from swarm_envs.envs.step_control import check_step_control
from swarm_envs.envs.task import observation_size
from train.evaluate.harness import check_policies, measure_row
from train.evaluate.measures import METRIC_DOCS
from train.evaluate.policies import SpaceMismatchError, describe_trained_env, policy_mode
from train.evaluate.report import (
    SWEEP_COLUMNS,
    SWEEP_CSV_KEYS,
    csv_cell,
    format_cell,
    sweep_summary,
    write_sweep_outputs,
)

__all__ = [
    "TRANSFER_FILES",
    "CentralPolicyError",
    "central_size",
    "check_transferable",
    "evaluate_transfer",
    "format_transfer_table",
    "size_configs",
    "write_transfer_outputs",
]

#: What a size-transfer evaluation writes (``--overwrite`` removes these).
TRANSFER_FILES = ("results.json", "summary.md", "transfer.csv", "transfer.png")


class CentralPolicyError(SpaceMismatchError):
    """A central policy (whole-swarm observation of fixed size) cannot be evaluated at
    other swarm sizes."""


def central_size(policy: Any, cfg: SwarmConfig) -> int | None:
    """The swarm size ``n ≥ 2`` whose central layout ``policy``'s spaces have
    (observation ``(n·obs_dim,)``, action ``(n·d,)``), or ``None`` when they are not a
    central layout for any size (a per-agent policy, a plain object, or spaces that fit
    nothing)."""
    obs_shape = tuple(getattr(getattr(policy, "observation_space", None), "shape", None) or ())
    act_shape = tuple(getattr(getattr(policy, "action_space", None), "shape", None) or ())
    k, d = observation_size(cfg), cfg.dim
    if len(obs_shape) != 1 or len(act_shape) != 1:
        return None
    n, rest = divmod(obs_shape[0], k)
    if rest or n < 2 or act_shape[0] != n * d:
        return None
    return n


def check_transferable(name: str, policy: Any, cfg: SwarmConfig) -> None:
    """Check that ``policy`` (called ``name``) is a shared per-agent policy for ``cfg``,
    so that it runs unchanged at any ``n_agents``.

    Raises:
        CentralPolicyError: its spaces are the central layout of some swarm size.
        SpaceMismatchError: its spaces fit neither layout (:func:`policy_mode`).
    """
    n = central_size(policy, cfg)
    if n is not None:
        k, d = observation_size(cfg), cfg.dim
        trained = describe_trained_env(policy)
        raise CentralPolicyError(
            f"policy {name!r} is a central policy: it maps the whole swarm's observation "
            f"({n * k},) = {n} agents × {k} to all agents' actions ({n * d},) (a model "
            f"trained on the Gymnasium env), so it fits N = {n} only and cannot be "
            "evaluated at other swarm sizes; size transfer needs a shared per-agent "
            f"policy (observation ({k},) → action ({d},), trained on the PettingZoo or "
            "vector env)" + (f"; the model was {trained}" if trained else "")
        )
    try:
        mode = policy_mode(policy, cfg)
    except SpaceMismatchError as err:
        trained = describe_trained_env(policy)
        extra = f"; the model was {trained}" if trained else ""
        raise SpaceMismatchError(f"policy {name!r}: {err}{extra}") from None
    assert mode == "shared", mode  # a central layout was refused above


def size_configs(cfg: SwarmConfig, n_agents: Sequence[int]) -> list[SwarmConfig]:
    """``cfg`` at each swarm size of ``n_agents``, in increasing order.

    Raises:
        ValueError: an empty list, a size that is not an integer ``≥ 1``, a size listed
            twice, or a config that is not valid at a size (e.g. per-agent arrays of
            the Lagrangian model, or a start predictably too dense for ``max_substeps``,
            :func:`~swarm_envs.envs.step_control.check_step_control`), naming the size.
    """
    sizes = list(n_agents)
    if not sizes:
        raise ValueError("n_agents must list at least one swarm size")
    for n in sizes:
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise ValueError(f"n_agents must be integers >= 1, got {n!r}")
    repeated = sorted({n for n in sizes if sizes.count(n) > 1})
    if repeated:
        raise ValueError(f"n_agents lists {', '.join(map(str, repeated))} more than once")
    out = []
    for n in sorted(sizes):
        try:
            sized = dataclasses.replace(cfg, n_agents=n)
            check_step_control(sized)
        except ValueError as err:
            raise ValueError(f"the config is not valid at n_agents={n}: {err}") from None
        out.append(sized)
    return out


def evaluate_transfer(
    policies: Mapping[str, Any],
    cfg: SwarmConfig | Any,
    n_agents: Sequence[int],
    episodes: int = 20,
    seed: int = 0,
    *,
    out_dir: str | Path | None = None,
    env_id: str = ENV_ID,
    deterministic: bool = True,
    progress: bool = True,
    plots: bool = True,
    extra: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Evaluate every policy, unchanged, at each swarm size of ``n_agents``.

    Args:
        policies: ``{name: policy}``; each a shared per-agent policy with SB3's
            ``predict`` (the :mod:`agents` controllers, models trained on the vector or
            PettingZoo env).
        cfg: the scenario, a :class:`SwarmConfig` or any swarm_envs env; only its
            ``n_agents`` is replaced. Its ``on_unstable`` is used as it is
            (``"truncate"`` counts unstable episodes instead of raising).
        n_agents: the swarm sizes (evaluated in increasing order).
        episodes: episodes per policy and size.
        seed: seed of the start states, shared by every policy (and size).
        out_dir: if given, write the outputs there (:func:`write_transfer_outputs`).
        env_id: recorded as ``"env"``.
        deterministic: passed to every ``predict``.
        progress: a tqdm progress bar per policy and size.
        plots: write ``transfer.png`` (with ``out_dir``).
        extra: more top-level entries for the results (e.g. the config path).

    Returns:
        ``{"env", "config", "n_agents", "episodes", "seed", "on_unstable", "metrics",
        "sizes": [{"n_agents", "backend", "policies": {name: measures}}, ...]}`` (JSON-
        ready; undefined measures are None). ``config`` is the scenario as given, its
        ``n_agents`` included; the sizes evaluated are ``n_agents``.

    Raises:
        CentralPolicyError: a central policy (checked for all before running).
        SpaceMismatchError: a policy's spaces fit neither layout.
        ValueError: bad sizes, or a config not valid at one of them (:func:`size_configs`).
        SwarmUnstableError: a step went unstable with ``on_unstable="raise"``.
    """
    cfg = swarm_config_of(cfg)
    if not policies:
        raise ValueError("no policies to evaluate")
    configs = size_configs(cfg, n_agents)
    for name, policy in policies.items():
        check_transferable(name, policy, cfg)
    check_policies(policies, cfg)  # warns where a model's env meant something else
    sizes = [
        {
            "n_agents": c.n_agents,
            **measure_row(
                policies,
                c,
                episodes,
                seed,
                label=f"N={c.n_agents}",
                deterministic=deterministic,
                progress=progress,
            ),
        }
        for c in configs
    ]
    results: dict[str, Any] = {
        "env": env_id,
        **dict(extra or {}),
        "config": as_dict(cfg),
        "n_agents": [c.n_agents for c in configs],
        "episodes": int(episodes),
        "seed": int(seed),
        "on_unstable": cfg.on_unstable,
        "metrics": METRIC_DOCS,
        "sizes": sizes,
    }
    if out_dir is not None:
        write_transfer_outputs(results, out_dir, plots=plots)
    return results


def _rows(results: Mapping[str, Any]) -> list[tuple[str, Mapping[str, Any], Mapping[str, Any]]]:
    """``(policy, size entry, measures)`` grouped by policy, sizes increasing."""
    names: list[str] = []
    for size in results["sizes"]:
        names += [n for n in size["policies"] if n not in names]
    return [
        (name, size, size["policies"][name])
        for name in names
        for size in results["sizes"]
        if name in size["policies"]
    ]


def format_transfer_table(results: Mapping[str, Any]) -> str:
    """The size-transfer measures as a markdown table, one row per policy and size
    (:data:`SWEEP_COLUMNS`); an undefined measure shows as ``—``, and the last column
    marks each size's best baseline."""
    headers = ["policy", "N", "backend", *(h for _, h, _ in SWEEP_COLUMNS), "best baseline"]
    lines = [
        "| " + " | ".join(headers) + " |",
        "|---|---:|---|" + "---:|" * len(SWEEP_COLUMNS) + ":---:|",
    ]
    for name, size, m in _rows(results):
        cells = [name, str(size["n_agents"]), size["backend"]]
        cells += [format_cell(m, key, spec) for key, _, spec in SWEEP_COLUMNS]
        cells.append("✓" if size.get("best_baseline") == name else "")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_transfer_csv(results: Mapping[str, Any], path: Path) -> Path:
    """``transfer.csv``: one row per policy and size (:data:`SWEEP_CSV_KEYS`)."""
    with path.open("w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(["policy", "n_agents", "backend", "episodes", *SWEEP_CSV_KEYS])
        for name, size, m in _rows(results):
            row = [name, size["n_agents"], size["backend"], results["episodes"]]
            writer.writerow(row + [csv_cell(m, k) for k in SWEEP_CSV_KEYS])
    return path


def _summary_markdown(results: Mapping[str, Any]) -> str:
    cfg = results["config"]
    sizes = ", ".join(str(n) for n in results["n_agents"])
    return sweep_summary(
        results,
        title="Size transfer",
        setting=f"Every policy unchanged at N = {sizes}; {results['episodes']} episodes per "
        f"policy and size, seed {results['seed']}, dt = {cfg['dt']}, max_steps = "
        f"{cfg['max_steps']}, on_unstable = {results['on_unstable']}",
        table=format_transfer_table(results),
        columns=SWEEP_COLUMNS,
    )


def write_transfer_outputs(
    results: Mapping[str, Any], out_dir: str | Path, *, plots: bool = True
) -> dict[str, Path]:
    """Write ``results.json``, ``summary.md``, ``transfer.csv`` and (``plots``)
    ``transfer.png`` into ``out_dir``; return their paths."""
    from train.evaluate.figures import plot_transfer

    return write_sweep_outputs(
        results,
        out_dir,
        stem="transfer",
        write_csv=write_transfer_csv,
        summary=_summary_markdown(results),
        plot=plot_transfer if plots else None,
    )
