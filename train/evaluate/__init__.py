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

Episodes run on the core that the config's ``backend`` and ``device`` pick
(:func:`swarm_envs.envs.backends.make_core`, float64) with ``batch = episodes``:
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
``final_centroid_distance``, ``final_fraction_arrived``; with step-size control,
``unstable_episodes`` (episodes truncated on an unstable step, ``info["unstable"]``) and
``mean_substeps`` (``info["substeps"]`` per integrated step). A measure that is
undefined (the time to goal when nothing succeeded) is ``None``: ``results.json`` never
holds NaN or infinity (``null`` there, ``—`` in the tables).

Size transfer (:func:`evaluate_transfer`): every shared policy, unchanged, at several
swarm sizes N, with a table, ``transfer.csv`` and ``transfer.png`` against N; a central
policy (fixed whole-swarm observation) is refused with :class:`CentralPolicyError`.

Robustness (:func:`evaluate_robustness`): every policy on the same seeded episodes at
each value of a perturbation sweep (failed agents, observation and action noise,
neighbour dropout), with a table, ``robustness.csv`` and ``robustness.png``.

Python API::

    from train.evaluate import evaluate_policies
    results = evaluate_policies({"potential": PotentialFieldController(cfg), "ppo": model},
                                cfg, episodes=20, seed=0, out_dir=None)

``out_dir`` also writes ``results.json``, ``summary.md``, ``curves.png`` and one GIF per
policy (:func:`write_outputs`). The console script is :mod:`train.cli_eval`.

Modules:

- :mod:`train.evaluate.policies`: :func:`policy_mode` (the layouts),
  :class:`SpaceMismatchError`, :func:`load_sb3_model`;
- :mod:`train.evaluate.episodes`: :func:`run_episodes` → :class:`EpisodeBatch`;
- :mod:`train.evaluate.measures`: :func:`summarize` and :data:`METRIC_DOCS`;
- :mod:`train.evaluate.harness`: :func:`evaluate_policies`;
- :mod:`train.evaluate.transfer`: :func:`evaluate_transfer` and its outputs;
- :mod:`train.evaluate.robustness`: :func:`evaluate_robustness` and its outputs;
- :mod:`train.evaluate.report`: :func:`write_outputs`, :func:`format_table`;
- :mod:`train.evaluate.figures`: ``curves.png``, the GIFs and ``transfer.png``.
"""

from __future__ import annotations

from train.evaluate.episodes import CURVE_KEYS, FINAL_KEYS, EpisodeBatch, run_episodes
from train.evaluate.harness import TrainedEnvWarning, check_policies, evaluate_policies
from train.evaluate.measures import METRIC_DOCS, json_safe, summarize
from train.evaluate.policies import (
    TRAINED_ENV,
    SpaceMismatchError,
    load_sb3_model,
    policy_mode,
    trained_env_record,
)
from train.evaluate.report import TABLE_COLUMNS, format_table, write_json, write_outputs
from train.evaluate.robustness import (
    ROBUSTNESS_FILES,
    evaluate_robustness,
    format_robustness_table,
)
from train.evaluate.transfer import (
    TRANSFER_FILES,
    CentralPolicyError,
    evaluate_transfer,
    format_transfer_table,
)

__all__ = [
    "CURVE_KEYS",
    "FINAL_KEYS",
    "METRIC_DOCS",
    "ROBUSTNESS_FILES",
    "TABLE_COLUMNS",
    "TRAINED_ENV",
    "TRANSFER_FILES",
    "CentralPolicyError",
    "EpisodeBatch",
    "SpaceMismatchError",
    "TrainedEnvWarning",
    "check_policies",
    "evaluate_policies",
    "evaluate_robustness",
    "evaluate_transfer",
    "format_robustness_table",
    "format_table",
    "format_transfer_table",
    "json_safe",
    "load_sb3_model",
    "policy_mode",
    "run_episodes",
    "summarize",
    "trained_env_record",
    "write_json",
    "write_outputs",
]
