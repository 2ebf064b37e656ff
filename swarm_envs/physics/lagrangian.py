"""Lagrangian gradient swarm model of Vanualailai & Sharma: value, gradients, integrator.

Reference: J. Vanualailai and B. Sharma, *A Lagrangian-based swarming behavior in the
absence of obstacles* (2010; seed ``004``), §§3–5, eqs. 3–7; ``docs/models.md`` §5.

Model. Agent ``i`` is a point ``x_i ∈ R^d`` inside a disk ("bin", eq. 3) of radius
``r_i``. With the swarm centroid ``x_c = (1/n) Σ_k x_k`` (§3: the paper's ``x_c`` is the
*moving centroid*, not a fixed target; it appears as ``x_i − (1/n) Σ_k x_k`` inside
``R_i`` in §4.1 and in eq. 6),

* ``R_i = ½|x_i − x_c|²`` (§4.1), ``R_ij = ½(|x_i − x_j|² − (r_i + r_j)²)`` (§4.2);
* ``L = Σ_i (γ_i R_i + Σ_{j≠i} β_ij R_i / R_ij)`` (§5.1), defined on
  ``D_1 = {all R_ij > 0}`` (no two bins overlap);
* first order (eqs. 6–7): ``ẋ_i = −α_i ⊙ ∂L/∂x_i`` with per-component ``α_i^s > 0``.

Two gradients are offered (``LagrangianParams.gradient``):

``"seed"`` — the printed eq. 6,
``∂L/∂x_i = (γ_i + Σ_{j≠i} β_ij/R_ij)(x_i − x_c) − 2 Σ_{j≠i} β_ij R_i/R_ij² (x_i − x_j)``.
This is *not* the gradient of ``L``: it drops the centroid's dependence on ``x_i``
(the ``−(1/n) Σ_m (...)`` term that §5.1 does cancel for ``Σ_i Ṙ_i`` but not once the
weights ``γ_i + Σ_j β_ij/R_ij`` differ between agents), it drops the terms in which
``x_i`` appears as the *partner* ``j`` of another agent's ``R_ji``, and it carries a
factor 2 that ``∂R_ij/∂x_i = x_i − x_j`` does not have. It is the form that produced
the paper's figures: its velocities do not sum to zero, so the centroid drifts
(the paper's "cruising", "leader-following", "random walk" and "circular motion").
``L`` is not a Lyapunov function for it and may increase.

``"exact"`` — the true gradient of ``L``, centroid dependence included:
``∂L/∂x_k = w_k e_k − (1/n) Σ_i w_i e_i − Σ_{j≠k} (B_kj + B_jk)(x_k − x_j)`` with
``e_i = x_i − x_c``, ``w_i = γ_i + Σ_{j≠i} β_ij/R_ij`` and ``B_ij = β_ij R_i/R_ij²``.
For it ``L̇ = −Σ α (∂L/∂x)² ≤ 0`` (Theorem 3) and no pair can reach ``R_ij = 0``. Since
``L`` is translation invariant, ``Σ_k ∂L/∂x_k = 0``: with the same ``α`` for every
agent and component the centroid never moves, so none of the paper's moving
behaviours exist under the exact gradient (they need the seed form or random ``α``).

Fixed centre. Passing ``goal`` replaces the moving centroid by that fixed point,
``R_i = ½|x_i − goal|²`` (an extension, not in the paper; then the exact gradient has
no ``(1/n) Σ_i`` term). ``goal=None`` (default) is the paper's centroid.

Heterogeneous parameters. ``alpha``, ``gamma``, ``beta`` and ``r`` are each a scalar
(the same for every agent/pair) or a tuple: ``gamma``/``r`` shaped ``(N,)``, ``alpha``
``(N,)`` or ``(N, d)`` (per component, ``α_i^s``), ``beta`` ``(N, N)`` (row ``i``,
column ``j`` is ``β_ij``; the diagonal is ignored; not necessarily symmetric, the paper's
"anisotropic, non-reciprocal" case). Tuples keep the dataclass frozen and hashable;
:meth:`LagrangianParams.randomized` draws the paper's random values from a Generator.

Arrays are shaped ``(..., N, d)``; pair terms are ``(..., N, N)`` arrays; nothing loops
over agents or pairs in Python.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from functools import cached_property
from typing import Any, NamedTuple

import numpy as np

from swarm_envs.physics._validation import check_goal, check_real, check_run, check_state

GRADIENTS = ("seed", "exact")

#: Per-substep floor on the pair clearance: a step is rejected if some pair would keep
#: less than this fraction of its current ``R_ij`` (so ``R_ij`` stays ``> 0``).
CLEARANCE_KEEP = 0.5
#: The gap a start keeps between every pair of bins, as a fraction of their radii's sum:
#: ``|x_i − x_j| ≥ (1 + START_GAP)(r_i + r_j)`` (:func:`well_separated`).
START_GAP = 0.02
#: Accepted substeps grow by this factor (capped by the frame length ``dt``).
STEP_GROWTH = 1.5
#: Below ``dt · MIN_STEP_FRACTION`` a substep is not attempted: the state is held (a
#: numerical equilibrium, where round-off alone decides whether ``L`` would decrease).
MIN_STEP_FRACTION = 2.0**-40
#: Exact gradient: a rejected substep whose predicted decrease ``h Σ α (∂L/∂x)²`` is below
#: this many ulps of ``L`` is not halved further; the state is held (round-off level).
ROUNDOFF_HOLD = 64.0


def _as_param(owner: str, name: str, value: Any, *, low: float, low_inclusive: bool) -> Any:
    """A validated float or (nested) tuple of floats."""
    if isinstance(value, (list, tuple, np.ndarray)):
        arr = np.asarray(value)
        if arr.dtype == object or arr.ndim not in (1, 2) or arr.size == 0:
            raise ValueError(
                f"{owner}.{name} must be a scalar or a non-empty 1-D/2-D array, got shape "
                f"{arr.shape}"
            )
        if not np.issubdtype(arr.dtype, np.number) or np.issubdtype(arr.dtype, np.bool_):
            raise ValueError(f"{owner}.{name} must hold real numbers, got {arr.dtype}")
        arr = arr.astype(np.float64)
        for item in arr.ravel():
            check_real(owner, name, float(item), low=low, low_inclusive=low_inclusive)
        return tuple(map(tuple, arr.tolist())) if arr.ndim == 2 else tuple(arr.tolist())
    return check_real(owner, name, value, low=low, low_inclusive=low_inclusive)


@dataclass(frozen=True)
class LagrangianParams:
    """Parameters of the Lagrangian gradient model (Vanualailai & Sharma, §5, eqs. 6–7).

    Every field is validated on construction: a non-finite or out-of-range value raises
    :class:`ValueError` naming the field and the allowed range. Array-valued fields are
    stored as tuples (see the module docstring for shapes); their agreement with the
    number of agents ``N`` is checked when the model is evaluated.

    Defaults are the paper's Fig. 1 set (``α = 1, γ = 2, β = 50``, bin radius 10) with
    the printed eq. 6 gradient.

    >>> LagrangianParams().gamma
    2.0
    >>> LagrangianParams(beta=0.0)
    Traceback (most recent call last):
    ...
    ValueError: LagrangianParams.beta must be in (0, inf), got 0.0
    """

    alpha: float | tuple[Any, ...] = 1.0
    """Convergence parameter ``α_i^s > 0`` (eqs. 6–7): scalar, ``(N,)`` or ``(N, d)``."""
    gamma: float | tuple[float, ...] = 2.0
    """Coupling parameter ``γ_i > 0`` (§5.1; attraction to the centre): scalar or ``(N,)``."""
    beta: float | tuple[tuple[float, ...], ...] = 50.0
    """Cohesion parameter ``β_ij > 0`` (§5.1; pair repulsion): scalar or ``(N, N)``."""
    r: float | tuple[float, ...] = 10.0
    """Bin (safety disk) radius ``r_i ≥ 0`` (eq. 3): scalar or ``(N,)``."""
    gradient: str = "seed"
    """``"seed"``: the printed eq. 6 (the paper's figures); ``"exact"``: ``∇L``."""
    step_tol: float = 0.01
    """Integrator only: largest Euler local-error estimate per substep, as a fraction of
    the smallest pair clearance ``√(2 min R_ij)`` (see :func:`simulate_lagrangian`),
    in ``(0, 1]``."""

    def __post_init__(self) -> None:
        owner = type(self).__name__
        for f in fields(self):
            name = f.name
            value = getattr(self, name)
            if name == "gradient":
                if value not in GRADIENTS:
                    raise ValueError(f"{owner}.gradient must be one of {GRADIENTS}, got {value!r}")
                continue
            if name == "step_tol":
                value = check_real(owner, name, value, low=0.0, high=1.0, low_inclusive=False)
            else:
                value = _as_param(owner, name, value, low=0.0, low_inclusive=name == "r")
            object.__setattr__(self, name, value)
        shapes = {"gamma": (1,), "r": (1,), "alpha": (1, 2), "beta": (2,)}
        for name, ndims in shapes.items():
            value = getattr(self, name)
            if isinstance(value, tuple):
                arr = np.asarray(value)
                if arr.ndim not in ndims:
                    raise ValueError(
                        f"{owner}.{name} must be a scalar or have {' or '.join(map(str, ndims))}"
                        f" dimension(s), got shape {arr.shape}"
                    )
                if name == "beta" and arr.shape[0] != arr.shape[1]:
                    raise ValueError(f"{owner}.beta must be square (N, N), got shape {arr.shape}")

    # ------------------------------------------------------------------ helpers
    @classmethod
    def randomized(
        cls,
        n: int,
        rng: np.random.Generator,
        *,
        alpha: float = 1.0,
        gamma: float = 2.0,
        beta: float = 50.0,
        r: float = 10.0,
        alpha_range: tuple[float, float] | None = None,
        gamma_range: tuple[float, float] | None = None,
        beta_range: tuple[float, float] | None = None,
        symmetric_beta: bool = False,
        d: int = 2,
        gradient: str = "seed",
        step_tol: float = 0.01,
    ) -> LagrangianParams:
        """Parameters with the paper's random draws (table 1; Figs. 3–5).

        Each ``*_range`` given replaces the scalar by uniform draws from ``rng``:
        ``alpha_range`` → ``α_i^s`` shaped ``(n, d)``, ``gamma_range`` → ``γ_i`` shaped
        ``(n,)`` (Fig. 3: ``(0.01, 1)``), ``beta_range`` → ``β_ij`` shaped ``(n, n)``
        (Figs. 4–5: ``(200, 500)``), drawn independently for every ordered pair unless
        ``symmetric_beta``. Draw order (for reproducibility): α, γ, β.

        >>> p = LagrangianParams.randomized(3, np.random.default_rng(0), gamma_range=(0.01, 1))
        >>> len(p.gamma), p.beta
        (3, 50.0)
        """
        if int(n) != n or n < 1:
            raise ValueError(f"n must be a positive integer, got {n!r}")
        n = int(n)
        a: Any = alpha
        g: Any = gamma
        b: Any = beta
        if alpha_range is not None:
            a = tuple(map(tuple, rng.uniform(*alpha_range, size=(n, d)).tolist()))
        if gamma_range is not None:
            g = tuple(rng.uniform(*gamma_range, size=n).tolist())
        if beta_range is not None:
            m = rng.uniform(*beta_range, size=(n, n))
            if symmetric_beta:
                m = np.triu(m, 1) + np.triu(m, 1).T
            np.fill_diagonal(m, beta_range[0])
            b = tuple(map(tuple, m.tolist()))
        return cls(alpha=a, gamma=g, beta=b, r=r, gradient=gradient, step_tol=step_tol)

    @classmethod
    def navigation(cls, **overrides: Any) -> LagrangianParams:
        """The SwarmNav default (``dynamics="lagrangian"``): the exact gradient, small bins.

        ``α = 1, γ = 0.5, β = 0.01``, bins of radius ``r = 0.05`` (two bins touch at the
        environment's collision radius 0.1, so the model cannot collide) and
        ``gradient="exact"``, for which ``L`` is a Lyapunov function.
        """
        values: dict[str, Any] = {
            "alpha": 1.0,
            "gamma": 0.5,
            "beta": 0.01,
            "r": 0.05,
            "gradient": "exact",
            "step_tol": 0.05,
        }
        return cls(**{**values, **overrides})

    @cached_property
    def _arrays(self) -> dict[str, np.ndarray]:
        return {
            name: np.asarray(getattr(self, name), dtype=np.float64)
            for name in ("alpha", "gamma", "beta", "r")
        }

    def arrays(self, n: int, d: int, dtype: Any = np.float64) -> dict[str, np.ndarray]:
        """Broadcast-ready arrays for ``n`` agents in ``d`` dimensions.

        Returns ``alpha`` ``(n, d)`` or scalar-shaped, ``gamma`` ``(n,)``, ``beta``
        ``(n, n)`` with a zero diagonal, ``r_sum`` ``(n, n)`` (``r_i + r_j``).

        Raises:
            ValueError: a tuple-valued field whose shape does not match ``n``/``d``.
        """
        owner = type(self).__name__
        raw = self._arrays
        expect = {"gamma": (n,), "r": (n,), "beta": (n, n)}
        for name, shape in expect.items():
            arr = raw[name]
            if arr.ndim and arr.shape != shape:
                raise ValueError(f"{owner}.{name} has shape {arr.shape}, the swarm needs {shape}")
        alpha = raw["alpha"]
        if alpha.ndim == 1:
            if alpha.shape != (n,):
                raise ValueError(f"{owner}.alpha has shape {alpha.shape}, the swarm needs ({n},)")
            alpha = np.repeat(alpha[:, None], d, axis=1)
        elif alpha.ndim == 2 and alpha.shape != (n, d):
            raise ValueError(f"{owner}.alpha has shape {alpha.shape}, the swarm needs ({n}, {d})")
        gamma = np.broadcast_to(raw["gamma"], (n,))
        beta = np.array(np.broadcast_to(raw["beta"], (n, n)))
        np.fill_diagonal(beta, 0.0)
        r = np.broadcast_to(raw["r"], (n,))
        return {
            "alpha": alpha.astype(dtype, copy=False),
            "gamma": gamma.astype(dtype),
            "beta": beta.astype(dtype),
            "r_sum": (r[:, None] + r[None, :]).astype(dtype),
        }


# ---------------------------------------------------------------------- geometry
def _terms(
    x: np.ndarray, params: LagrangianParams, goal: Any | None
) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(arrays, e, R_i, R_ij, inv_R_ij)``; ``R_ij``'s diagonal is ``+inf``, ``1/R_ij``'s 0."""
    n, d = x.shape[-2], x.shape[-1]
    arr = params.arrays(n, d, x.dtype)
    if goal is None:
        centre = x.mean(axis=-2, keepdims=True)
    else:
        centre = check_goal(goal, x)[..., None, :]
    e = x - centre
    R_i = 0.5 * np.einsum("...ik,...ik->...i", e, e)
    # |x_i − x_j|² from offsets (not the Gram trick) to keep precision for nearby agents.
    dist2 = np.zeros((*x.shape[:-1], n), dtype=x.dtype)
    for k in range(d):  # loop over the d ≤ 3 components only
        diff = x[..., :, None, k] - x[..., None, :, k]
        dist2 += diff * diff
    R_ij = 0.5 * (dist2 - arr["r_sum"] ** 2)
    eye = np.eye(n, dtype=bool)
    R_ij = np.where(eye, np.inf, R_ij)
    with np.errstate(divide="ignore"):
        inv = np.where(eye, 0.0, 1.0 / np.where(eye, 1.0, R_ij))
    return arr, e, R_i, R_ij, inv.astype(x.dtype, copy=False)


def pair_clearance(x: np.ndarray, params: LagrangianParams) -> np.ndarray:
    """``R_ij = ½(|x_i − x_j|² − (r_i + r_j)²)`` (§4.2), ``(..., N, N)``, diagonal ``+inf``.

    >>> x = np.array([[0.0, 0.0], [3.0, 4.0]])
    >>> float(pair_clearance(x, LagrangianParams(r=1.0))[0, 1])  # ½(25 − 4)
    10.5
    """
    x, _ = check_state(x)
    return _terms(x, params, None)[3]


def min_pair_clearance(x: np.ndarray, params: LagrangianParams) -> np.ndarray:
    """``min_{i≠j} R_ij`` shaped ``(...)`` (``+inf`` for a single agent)."""
    return pair_clearance(x, params).min(axis=(-2, -1))


def lagrangian_value(
    x: np.ndarray, params: LagrangianParams, goal: Any | None = None
) -> np.ndarray:
    """``L = Σ_i (γ_i R_i + Σ_{j≠i} β_ij R_i / R_ij)`` (§5.1), shaped ``(...)``.

    ``L`` is defined on ``D_1`` (all ``R_ij > 0``); outside it (some bins overlap) the
    value is ``+inf``. ``goal`` replaces the centroid by a fixed centre (module doc).

    >>> x = np.array([[-2.0, 0.0], [2.0, 0.0]])  # R_i = 2, R_12 = ½(16 − 4) = 6
    >>> float(lagrangian_value(x, LagrangianParams(gamma=1.0, beta=3.0, r=1.0)))
    6.0
    """
    x, _ = check_state(x)
    arr, _, R_i, R_ij, inv = _terms(x, params, goal)
    w = arr["gamma"] + np.einsum("...ij,ij->...i", inv, arr["beta"])
    value = np.einsum("...i,...i->...", w, R_i)
    outside = (R_ij <= 0).any(axis=(-2, -1))
    return np.where(outside, np.inf, value)


def lagrangian_gradient(
    x: np.ndarray,
    params: LagrangianParams,
    goal: Any | None = None,
    *,
    gradient: str | None = None,
) -> np.ndarray:
    """``∂L/∂x_i`` for every agent, shaped like ``x``: eq. 6 (``"seed"``) or ``∇L``.

    Args:
        x: positions ``(..., N, d)`` in ``D_1`` (all ``R_ij > 0``; outside it the
            formulas are evaluated as written and mean nothing).
        params: model parameters; ``params.gradient`` picks the form.
        goal: fixed centre replacing the centroid (``None``: the paper's centroid).
        gradient: overrides ``params.gradient`` (``"seed"`` or ``"exact"``).

    ``"seed"``: ``(γ_i + Σ_j β_ij/R_ij)(x_i − x_c) − 2 Σ_j β_ij R_i/R_ij² (x_i − x_j)``.
    ``"exact"``: ``w_k e_k − [(1/n) Σ_i w_i e_i] − Σ_j (B_kj + B_jk)(x_k − x_j)`` (the
    bracket only for the centroid), ``B_ij = β_ij R_i/R_ij²``, ``w_i = γ_i + Σ_j β_ij/R_ij``.

    >>> x = np.array([[-2.0, 0.0], [2.0, 0.0]])
    >>> p = LagrangianParams(gamma=1.0, beta=3.0, r=1.0)
    >>> lagrangian_gradient(x, p, gradient="exact").tolist()  # dL/ds = 5/3, s = |x_2 − x_1|
    [[-1.6666666666666667, 0.0], [1.6666666666666667, 0.0]]
    """
    x, _ = check_state(x)
    form = params.gradient if gradient is None else gradient
    if form not in GRADIENTS:
        raise ValueError(f"gradient must be one of {GRADIENTS}, got {form!r}")
    arr, e, R_i, _, inv = _terms(x, params, goal)
    beta = arr["beta"]
    w = arr["gamma"] + np.einsum("...ij,ij->...i", inv, beta)
    grad = w[..., None] * e
    B = beta * (R_i[..., :, None] * inv * inv)  # β_ij R_i / R_ij²
    if form == "seed":
        S = 2.0 * B
    else:
        S = B + np.swapaxes(B, -1, -2)
        if goal is None:
            grad -= grad.mean(axis=-2, keepdims=True)
    # Σ_j S_ij (x_i − x_j) = (Σ_j S_ij) x_i − (S x)_i
    grad -= S.sum(axis=-1)[..., None] * x - S @ x
    return grad


def lagrangian_velocity(
    x: np.ndarray, params: LagrangianParams, goal: Any | None = None
) -> np.ndarray:
    """``ẋ_i = −α_i ⊙ ∂L/∂x_i`` (eqs. 6–7), shaped like ``x``."""
    x, _ = check_state(x)
    alpha = params.arrays(x.shape[-2], x.shape[-1], x.dtype)["alpha"]
    return -alpha * lagrangian_gradient(x, params, goal)


# ---------------------------------------------------------------------- integrator
def simulate_lagrangian(
    params: LagrangianParams,
    x0: Any,
    v0: Any,
    *,
    dt: float,
    steps: int,
    goal: Any | None = None,
    rng: np.random.Generator | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Integrate eq. 7 from ``x0``, recording ``steps + 1`` frames ``dt`` apart.

    First order: the state is the positions alone. ``v0`` is only checked for shape
    (it must match ``x0``; pass ``np.zeros_like(x0)``) and is otherwise ignored; the
    returned ``vs[k]`` is the model velocity ``ẋ = −α ∇L`` at ``xs[k]`` (so ``vs[0]``
    is computed, not ``v0``). ``rng`` is accepted for signature compatibility with
    :func:`swarm_envs.physics.simulate`; the model is deterministic and ignores it.

    Step rule (explicit Euler with adaptive substeps, per batch element). Each frame
    of length ``dt`` is covered by Euler substeps ``x' = x + h ẋ(x)``. A trial substep is
    accepted only if

    1. every pair keeps at least :data:`CLEARANCE_KEEP` of its clearance,
       ``R_ij(x') ≥ ½ R_ij(x)`` (hence ``R_ij`` stays ``> 0`` for ever);
    2. the local-error estimate ``(h/2) max_i |ẋ_i(x') − ẋ_i(x)|`` is at most
       ``params.step_tol · √(2 min R_ij(x))`` (for one agent: of ``√(2 R_1)``);
    3. for ``gradient="exact"`` only: ``L(x') ≤ L(x)`` (``L`` never increases along
       the computed trajectory; for eq. 6 ``L`` is not a Lyapunov function).

    A rejected substep is halved; an accepted one lets the next grow by
    :data:`STEP_GROWTH` (capped at ``dt``). If the substep falls below
    ``dt · MIN_STEP_FRACTION`` while only rule 3 rejects it, the state is held for the
    rest of the frame (a numerical equilibrium where round-off decides the sign of
    ``ΔL``); for the exact gradient the same happens once the predicted decrease
    ``h Σ α (∂L/∂x)²`` is below :data:`ROUNDOFF_HOLD` ulps of ``L``. Where rule 1 or 2
    still rejects it, the state cannot be integrated and ``RuntimeError`` is raised.
    Batch elements choose their substeps independently, so a batch equals its elements
    run one by one.

    Args:
        params: model parameters (``params.gradient`` picks eq. 6 or ``∇L``).
        x0: initial positions ``(..., N, d)`` with all ``R_ij > 0``.
        v0: array shaped like ``x0`` (ignored; first-order model).
        dt: frame interval (> 0).
        steps: number of frames after the first (≥ 0).
        goal: fixed centre replacing the centroid, broadcastable to ``(..., d)``.
        rng: ignored.

    Returns:
        ``(xs, vs)``, each ``(steps + 1, ..., N, d)``.

    Raises:
        ValueError: bad ``dt``/``steps``, shapes, or a start with some ``R_ij ≤ 0``.
        RuntimeError: a frame the step rules cannot integrate (bins all but touching:
            rule 1 or 2 rejects even a substep of ``dt · MIN_STEP_FRACTION``).

    >>> x0 = np.array([[-3.0, 0.0], [3.0, 0.0], [0.0, 4.0]])
    >>> p = LagrangianParams(gamma=1.0, beta=1.0, r=0.5, gradient="exact")
    >>> xs, vs = simulate_lagrangian(p, x0, np.zeros_like(x0), dt=0.1, steps=20)
    >>> L = lagrangian_value(xs, p)
    >>> xs.shape, bool(np.all(np.diff(L) <= 0))
    ((21, 3, 2), True)
    """
    del rng
    x, v_in = check_state(x0, v0)
    del v_in
    dt, steps = check_run("simulate_lagrangian", dt, steps)
    x = np.array(x, copy=True)
    goal_arr = None if goal is None else check_goal(goal, x)
    check_start_clearance(x, params)
    v = lagrangian_velocity(x, params, goal_arr)
    xs = np.empty((steps + 1, *x.shape), dtype=x.dtype)
    vs = np.empty_like(xs)
    xs[0], vs[0] = x, v
    h = None
    for k in range(1, steps + 1):
        frame = lagrangian_frame(x, params, dt=dt, goal=goal_arr, substep=h)
        if frame.over_cap.any():  # no cap here: a state the step rules cannot integrate
            raise RuntimeError(
                f"simulate_lagrangian: frame {k} cannot be integrated: a pair of bins is "
                f"all but touching (min R_ij = {float(min_pair_clearance(x, params).min()):.3g}), "
                "so no substep above dt·2^-40 keeps the step rules; start the bins further "
                "apart (well_separated) or use smaller lagrangian r"
            )
        x, v, h = frame.x, frame.v, frame.substep
        xs[k], vs[k] = x, v
    return xs, vs


def well_separated(x: np.ndarray, params: LagrangianParams, gap: float = START_GAP) -> np.ndarray:
    """Whether every pair of ``x`` ``(..., N, d)`` is at least ``(1 + gap)(r_i + r_j)``
    apart (and ``R_ij > 0``), shaped ``(...)``: a start the step rules can integrate.

    Bins that nearly touch make ``R_ij`` nearly 0, and ``L`` and the velocity so large
    that no substep above ``dt · MIN_STEP_FRACTION`` passes the step rules: the swarm
    would be held where it starts. With ``gap = 0.02`` the pair needs
    ``R_ij ≥ ½((1.02)² − 1)(r_i + r_j)²``; point bins (``r = 0``) only ``R_ij > 0``.

    >>> p = LagrangianParams(r=0.05)
    >>> bool(well_separated(np.array([[0.0, 0.0], [0.1001, 0.0]]), p))
    False
    >>> bool(well_separated(np.array([[0.0, 0.0], [0.103, 0.0]]), p))
    True
    """
    if gap < 0:
        raise ValueError(f"gap must be >= 0, got {gap}")
    x, _ = check_state(x)
    n = x.shape[-2]
    if n < 2:
        return np.ones(x.shape[:-2], dtype=bool)
    arr, _, _, R_ij, _ = _terms(x, params, None)
    need = 0.5 * ((1.0 + gap) ** 2 - 1.0) * arr["r_sum"] ** 2
    return np.asarray(((R_ij > 0) & (R_ij >= need)).all(axis=(-2, -1)))


def check_start_clearance(x: np.ndarray, params: LagrangianParams) -> None:
    """Raise :class:`ValueError` unless every pair clearance ``R_ij`` of ``x`` is ``> 0``."""
    if x.shape[-2] > 1:
        clear = pair_clearance(x, params)
        if not np.all(clear > 0):
            raise ValueError(
                "x0 must have every pair clearance R_ij > 0 (bins must not overlap), "
                f"got min R_ij = {float(clear.min()):.6g}"
            )


class LagrangianFrame(NamedTuple):
    """One frame of :func:`lagrangian_frame`: the new positions ``x``, the velocity ``v``
    (``ẋ`` at ``x``, control included), the substep length to carry into the next frame,
    the accepted substeps per batch element (``substeps``, float) and where the frame
    was cut short at ``max_substeps`` or held in a state the step rules cannot integrate
    (``over_cap``, bool)."""

    x: np.ndarray
    v: np.ndarray
    substep: np.ndarray
    substeps: np.ndarray
    over_cap: np.ndarray


def lagrangian_step(
    x: np.ndarray,
    params: LagrangianParams,
    *,
    dt: float,
    goal: Any | None = None,
    control: np.ndarray | None = None,
    substep: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(x', v', substep')`` of :func:`lagrangian_frame` (no cap on the substeps)."""
    frame = lagrangian_frame(x, params, dt=dt, goal=goal, control=control, substep=substep)
    return frame.x, frame.v, frame.substep


def lagrangian_frame(
    x: np.ndarray,
    params: LagrangianParams,
    *,
    dt: float,
    goal: Any | None = None,
    control: np.ndarray | None = None,
    substep: np.ndarray | None = None,
    max_substeps: int | None = None,
) -> LagrangianFrame:
    """Advance eq. 7 by one frame ``dt`` with the safe substep rule of :func:`simulate_lagrangian`.

    ``ẋ_i = −α_i ⊙ ∂L/∂x_i + u_i``: ``control`` ``u`` (shaped like ``x``, held over the
    frame) is added to the model velocity, as the SwarmNav environments apply an action
    (``docs/models.md`` §6). The substep rules 1 (each pair keeps half its clearance, so no
    ``R_ij`` ever reaches 0, whatever the control) and 2 (local error) always apply; rule
    3 (``L`` never increases, exact gradient) applies only without control, since a
    control may rightly raise ``L``.

    Args:
        x: positions ``(..., N, d)`` with every ``R_ij > 0`` (not re-checked here).
        params: model parameters.
        dt: frame length, ``> 0``.
        goal: fixed centre replacing the centroid, broadcastable to ``(..., d)``.
        control: added velocity shaped like ``x``, or ``None``.
        substep: the substep length ``(...)`` carried from the previous frame (``None``:
            start at ``dt``).
        max_substeps: the most substeps a batch element may accept in this frame
            (``None``: no cap). An element that reaches it with time left stops there,
            its state held, and is marked in ``over_cap``; so is one whose substep falls
            below ``dt · MIN_STEP_FRACTION`` while rule 1 or 2 still rejects it (a state
            the rules cannot integrate, not an equilibrium).

    Returns:
        A :class:`LagrangianFrame`.

    >>> x = np.array([[-3.0, 0.0], [3.0, 0.0], [0.0, 4.0]])
    >>> p = LagrangianParams(gamma=1.0, beta=1.0, r=0.5, gradient="exact")
    >>> x1, v1, h = lagrangian_step(x, p, dt=0.1)
    >>> bool(lagrangian_value(x1, p) <= lagrangian_value(x, p)), x1.shape
    (True, (3, 2))
    """
    goal = None if goal is None else check_goal(goal, x)
    exact = params.gradient == "exact" and control is None
    n, d = x.shape[-2], x.shape[-1]
    alpha = params.arrays(n, d, x.dtype)["alpha"]
    # Batch elements choose their substeps independently; each iteration evaluates only
    # the elements still inside the frame (a stiff swarm does not slow the others).
    batch = x.shape[:-2]
    B = int(np.prod(batch, dtype=np.int64))
    xf = np.array(x, copy=True).reshape(B, n, d)
    gf = None if goal is None else np.broadcast_to(goal, (*batch, d)).reshape(B, d)
    cf = None if control is None else np.broadcast_to(control, x.shape).reshape(B, n, d)

    def evaluate(y: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        g = None if gf is None else gf[rows]
        vel = -alpha * lagrangian_gradient(y, params, g)
        if cf is not None:
            vel = vel + cf[rows]
        clear = pair_clearance(y, params)
        val = lagrangian_value(y, params, g) if exact else np.zeros(len(rows))
        return vel, clear, val

    v, clear, L = evaluate(xf, np.arange(B))
    h = np.full(B, dt)
    if substep is not None:
        h = np.array(np.broadcast_to(substep, batch), dtype=float).reshape(B)
    h_min = dt * MIN_STEP_FRACTION
    remaining = np.full(B, dt)
    accepted = np.zeros(B)
    over_cap = np.zeros(B, dtype=bool)
    while (rows := np.flatnonzero(remaining > 0)).size:
        h_old = h[rows]
        h_try = np.minimum(h_old, remaining[rows])
        x_try = xf[rows] + h_try[:, None, None] * v[rows]
        v_try, clear_try, L_try = evaluate(x_try, rows)
        if n > 1:
            min_clear = clear[rows].min(axis=(-2, -1))
            ok = np.all(clear_try >= CLEARANCE_KEEP * clear[rows], axis=(-2, -1))
        else:
            x_rows = xf[rows]
            centre = x_rows.mean(axis=-2, keepdims=True) if gf is None else gf[rows][:, None, :]
            off = x_rows - centre
            min_clear = 0.5 * np.einsum("mik,mik->m", off, off)
            if cf is not None:  # a single controlled agent: scale by its own motion
                own = dt * np.abs(cf[rows]).max(axis=(-2, -1))
                min_clear = np.maximum(min_clear, 0.5 * own**2)
            ok = np.ones(rows.size, dtype=bool)
        dv = v_try - v[rows]
        err = 0.5 * h_try * np.sqrt(np.einsum("mik,mik->mi", dv, dv).max(axis=-1))
        ok &= err <= params.step_tol * np.sqrt(2.0 * np.maximum(min_clear, 0.0))
        safe = ok.copy()  # rules 1 and 2: the substep can be integrated
        if exact:
            ok &= L_try <= L[rows]
        acc = rows[ok]
        xf[acc], v[acc], clear[acc], L[acc] = x_try[ok], v_try[ok], clear_try[ok], L_try[ok]
        left = remaining[acc] - h_try[ok]
        remaining[acc] = np.where(left <= dt * 1e-12, 0.0, left)
        accepted[acc] += 1
        if max_substeps is not None:
            capped = acc[(accepted[acc] >= max_substeps) & (remaining[acc] > 0)]
            over_cap[capped] = True
            remaining[capped] = 0.0
        grown = np.where(h_try < h_old, h_old, np.minimum(h_try * STEP_GROWTH, dt))
        new_h = np.where(ok, grown, h_try * 0.5)
        stuck = ~ok & (new_h < h_min)
        # Held while rule 1 or 2 still rejects the shortest substep: no equilibrium, a
        # state the rules cannot integrate (bins all but touching). Marked, not silent.
        over_cap[rows[stuck & ~safe]] = True
        if exact:
            # Predicted decrease h Σ α (∂L/∂x)² lost in L's round-off: hold the state
            # (only where rule 3 alone rejects the substep).
            v_rows = v[rows]
            drop = h_try * np.einsum("mik,mik->m", v_rows, v_rows / alpha)
            eps = np.finfo(x.dtype).eps
            stuck |= ~ok & safe & (drop <= ROUNDOFF_HOLD * eps * np.abs(L[rows]))
        remaining[rows[stuck]] = 0.0
        h[rows] = np.where(stuck, np.maximum(h_try, h_min), new_h)
    return LagrangianFrame(
        xf.reshape(x.shape),
        v.reshape(x.shape),
        h.reshape(batch),
        accepted.reshape(batch),
        over_cap.reshape(batch),
    )


__all__ = [
    "GRADIENTS",
    "START_GAP",
    "LagrangianFrame",
    "LagrangianParams",
    "check_start_clearance",
    "lagrangian_frame",
    "lagrangian_gradient",
    "lagrangian_step",
    "lagrangian_value",
    "lagrangian_velocity",
    "min_pair_clearance",
    "pair_clearance",
    "simulate_lagrangian",
    "well_separated",
]
