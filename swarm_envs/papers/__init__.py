"""Reproductions of the seed papers' figures, one module per paper.

Physics and metrics only: nothing here imports the environments, the agents or the
trainers. The console script ``swarm-reproduce`` (:mod:`swarm_envs.papers.cli`) and
``make reproduce`` call these functions and write PNG, JSON and GIF files.

- :mod:`swarm_envs.papers.mabrouk_mcinnes`: Mabrouk & McInnes, *Social potential model
  to simulate emergent behaviour for swarm robots*, Figs. 1, 4–5, 6–8, 9, 10 and 11.
"""

from swarm_envs.papers.mabrouk_mcinnes import (
    FIGURES,
    RunSetup,
    classify_trend,
    fig1_polarization_vs_beta,
    fig4_5_variance_and_angular_momentum,
    fig6_8_alignment_sweep,
    fig9_range_ratio_sweep,
    fig10_amplitude_ratio_sweep,
    fig11_navigation,
)

__all__ = [
    "FIGURES",
    "RunSetup",
    "classify_trend",
    "fig1_polarization_vs_beta",
    "fig4_5_variance_and_angular_momentum",
    "fig6_8_alignment_sweep",
    "fig9_range_ratio_sweep",
    "fig10_amplitude_ratio_sweep",
    "fig11_navigation",
]
