"""Parameter sweeps: a grid of physics (or task) parameters × seeds, run locally or on Ray Tune.

A sweep (``configs/sweeps/*.yaml`` → :class:`SweepConfig`) names a **task**, a
**grid** (parameter → list of values; the trials are the Cartesian product of the
lists, times the seeds) and the fixed setup. Two tasks:

``relax``
    The passive social-potential swarm of Mabrouk & McInnes (Figs. 1–10): agents start
    uniform in a disc, the physics runs for ``duration`` time units, and the group
    statistics of :mod:`swarm_envs.metrics` are recorded at the end (``final_*``) and
    averaged over ``samples`` evenly spaced times (``time_mean_*``). Grid keys: any
    :class:`~swarm_envs.physics.SocialPotentialParams` field (``l_r``, ``C_r``,
    ``C_o``, ``beta``, …) or a :class:`RelaxSetup` field (``n_agents``, ``dt``, …).
``navigate``
    One SwarmNav episode of an analytic controller (default ``potential``, the paper's
    goal sink, eq. 21) per trial, measured as :mod:`train.evaluate` measures it. Grid
    keys: ``SocialPotentialParams`` fields (the controller's ``C_g``, ``l_g``) or scalar
    :class:`~swarm_envs.config.SwarmConfig` fields (``n_agents``, ``u_max``, …).

Every trial is the same pure function, :func:`run_trial`, of a plain-data spec
(:meth:`SweepConfig.trial_specs`); its random start comes from
``numpy.random.SeedSequence([base_seed, seed])`` (common random numbers: every grid
point sees the same starts for a seed, as in the paper's sweeps), or with
``common_random_numbers: false`` from ``[base_seed, seed, hash(grid point)]``. So the
two engines give the same numbers for the same grid and seeds:

- ``local``: the trials one after another in this process (no Ray);
- ``ray``: one Ray Tune trial per grid point × seed, spread over a local Ray or a
  cluster (``address``), ``cpus_per_trial`` CPUs each.

Results (:func:`write_outputs`): ``trials.csv`` (one row per trial), ``summary.csv``
(per grid point: mean and population std over seeds of every measure),
``results.json`` (both, with the config), ``sweep.png`` (the ``plot`` measures against
the first grid key, one line per value of the others, error bars ± std over seeds) and
``sweep_config.yaml``.

Modules:

- :mod:`train.sweep.measures`: the tasks and the measure columns of each;
- :mod:`train.sweep.config`: :class:`SweepConfig`, its setups and the trial specs;
- :mod:`train.sweep.trials`: :func:`run_trial` and :func:`trial_seed`;
- :mod:`train.sweep.engines`: :func:`run_local`, :func:`run_ray` and :func:`run_sweep`;
- :mod:`train.sweep.results`: :class:`SweepResult`, :func:`summarize_rows` and
  :func:`write_outputs`;
- :mod:`train.sweep.plot`: :func:`plot_summary` (``sweep.png``).

>>> sc = sweep_config_from_mapping({"grid": {"l_r": [0.2, 0.4]}, "seeds": 2,
...     "relax": {"n_agents": 5, "duration": 0.5, "dt": 0.05, "samples": 3}})
>>> [(s["point"], s["seed"]) for s in sc.trial_specs()]
[({'l_r': 0.2}, 0), ({'l_r': 0.2}, 1), ({'l_r': 0.4}, 0), ({'l_r': 0.4}, 1)]
>>> rows = run_local(sc.trial_specs())
>>> rows == run_local(sc.trial_specs()), rows[0]["final_expanse"] > 0
(True, True)
"""

from __future__ import annotations

from train.sweep.config import (
    NavigateSetup,
    RelaxSetup,
    SweepConfig,
    load_sweep_config,
    sweep_config_from_mapping,
)
from train.sweep.engines import ENGINES, run_local, run_ray, run_sweep
from train.sweep.measures import (
    DEFAULT_PLOT,
    NAVIGATE_MEASURES,
    RELAX_STATISTICS,
    TASKS,
    measure_columns,
)
from train.sweep.plot import plot_summary
from train.sweep.results import SweepResult, summarize_rows, write_outputs
from train.sweep.trials import run_trial, trial_seed

__all__ = [
    "DEFAULT_PLOT",
    "ENGINES",
    "NAVIGATE_MEASURES",
    "RELAX_STATISTICS",
    "TASKS",
    "NavigateSetup",
    "RelaxSetup",
    "SweepConfig",
    "SweepResult",
    "load_sweep_config",
    "measure_columns",
    "plot_summary",
    "run_local",
    "run_ray",
    "run_sweep",
    "run_trial",
    "summarize_rows",
    "sweep_config_from_mapping",
    "trial_seed",
    "write_outputs",
]
