"""Reproductions of Naterop, Petrides & Prasad, *Implementing two mathematical swarm models*
(seed ``003``): the zone model (``zone.py``, their §4.1, table 3) and the piecewise force
model (``piecewise.py``, their §4.2, table 2)."""
