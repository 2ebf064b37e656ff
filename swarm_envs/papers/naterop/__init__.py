"""Reproductions of Naterop, Petrides & Prasad, *Implementing two mathematical swarm models*
(seed ``003``): the zone model (:mod:`~swarm_envs.papers.naterop.zone`, their §4.1,
table 3) and the piecewise force model (:mod:`~swarm_envs.papers.naterop.piecewise`,
their §4.2, table 2), two papers of the registry. Their claims are in
:mod:`~swarm_envs.papers.naterop.claims`, their plots in
:mod:`~swarm_envs.papers.naterop.plots`."""
