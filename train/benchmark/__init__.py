"""The benchmark: every task × dynamics × policy of a matrix, with confidence intervals.

``swarm-benchmark`` (``make benchmark``; ``docs/benchmark.md``) trains the learned
policy of every entry of ``configs/benchmark/results.yaml`` with several seeds,
evaluates it and the analytic baselines on the same seeded episodes, and writes
``results.json``, ``results.md`` and ``results.png`` with 95 % bootstrap intervals.

Modules:

- :mod:`train.benchmark.matrix`: the matrix file (:func:`load_matrix`, :class:`Entry`);
- :mod:`train.benchmark.run`: training (resumable) and evaluation of one entry;
- :mod:`train.benchmark.stats`: the hierarchical bootstrap (:func:`summarize_runs`);
- :mod:`train.benchmark.report`: the JSON, Markdown and plot writers;
- :mod:`train.benchmark.cli`: the console script.
"""

from __future__ import annotations

from train.benchmark.matrix import DEFAULT_MATRIX, Entry, Evaluation, Matrix, load_matrix
from train.benchmark.stats import bootstrap, summarize_runs

__all__ = [
    "DEFAULT_MATRIX",
    "Entry",
    "Evaluation",
    "Matrix",
    "bootstrap",
    "load_matrix",
    "summarize_runs",
]
