"""The few array operations the shared definitions use, for numpy arrays and torch tensors.

Every law, statistic, observation feature and reward term of the package is written
once, against an :class:`ArrayNamespace`, and executed by each backend with its own
arrays: numpy (the dense and cut-off cores, the public physics functions) or torch (the
torch core, plain or compiled, on any device). This module holds the operations whose
spelling differs between the two libraries; operators (``+``, ``*``, ``<``, indexing,
``.sum(axis)`` is *not* shared, use :meth:`ArrayNamespace.sum`) work on both as they are.

>>> import numpy as np
>>> xp = namespace(np.zeros(3))
>>> xp.name, float(xp.sum(xp.exp(np.zeros(3)), axis=-1))
('numpy', 3.0)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["NUMPY", "SCALAR", "ArrayNamespace", "namespace", "torch_namespace"]

Array = Any


class ArrayNamespace:
    """numpy's operations under the names the shared definitions call.

    :class:`TorchNamespace` gives torch's under the same names. Arguments named
    ``axis`` take an int or a tuple of ints, as in numpy.
    """

    name = "numpy"
    inf = math.inf
    #: How the pair energy's exponentials are evaluated (``pair_law``'s
    #: ``potential_decay``): ``None`` reuses the force's.
    potential_decay: Any = None

    def exp(self, a: Array) -> Array:
        return np.exp(a)

    def maximum(self, a: Array, b: Array) -> Array:
        """The elementwise maximum of two arrays of the same shape."""
        return np.maximum(a, b)

    def exp_temp(self, a: Array) -> Array:
        """``e^a`` for a temporary ``a`` the caller does not read again (numpy writes
        the result into it)."""
        return np.exp(a, out=a) if isinstance(a, np.ndarray) else np.exp(a)

    def sqrt(self, a: Array) -> Array:
        return np.sqrt(a)

    def reciprocal_temp(self, a: Array) -> Array:
        """``1/a`` for a temporary ``a`` (in place for numpy, as :meth:`exp_temp`)."""
        return np.reciprocal(a, out=a) if isinstance(a, np.ndarray) else 1.0 / a

    def sqrt_temp(self, a: Array) -> Array:
        """``√a`` for a temporary ``a`` (in place for numpy, as :meth:`exp_temp`)."""
        return np.sqrt(a, out=a) if isinstance(a, np.ndarray) else np.sqrt(a)

    def abs(self, a: Array) -> Array:
        return np.abs(a)

    def where(self, cond: Array, a: Array, b: Array) -> Array:
        return np.where(cond, a, b)

    def clip(self, a: Array, low: float | None = None, high: float | None = None) -> Array:
        if high is None:
            return a if low is None else np.maximum(a, low)
        if low is None:
            return np.minimum(a, high)
        return np.clip(a, low, high)

    def sum(self, a: Array, axis: int | tuple[int, ...]) -> Array:
        return a.sum(axis=axis) if isinstance(a, np.ndarray) else np.sum(a, axis=axis)

    def mean(self, a: Array, axis: int | tuple[int, ...]) -> Array:
        return a.mean(axis=axis) if isinstance(a, np.ndarray) else np.mean(a, axis=axis)

    def sum_product(self, a: Array, b: Array) -> Array:
        """``Σ_j a[..., j] b[..., j]``: the sum of products over the last axis."""
        return np.einsum("...j,...j->...", a, b)

    def sum_components(self, a: Array) -> Array:
        """The sum over a short last axis (the d = 2 or 3 components of a vector),
        written component by component: a compiler fuses that into the surrounding
        loops, where a reduction over an axis of length 2 or 3 would stand alone."""
        total = a[..., 0]
        for k in range(1, a.shape[-1]):
            total = total + a[..., k]
        return total

    def norm(self, a: Array) -> Array:
        """The Euclidean norm over the last axis (the vector's components)."""
        return self.sqrt(self.sum_components(a * a))

    def sum_agents(self, a: Array) -> Array:
        """``Σ_i a[..., i, :]``: vectors ``(..., N, d)`` summed over the agents."""
        return a.sum(axis=-2)

    def mean_agents(self, a: Array) -> Array:
        """The mean of vectors ``(..., N, d)`` over the agents, shaped ``(..., d)``."""
        return a.mean(axis=-2)

    def amax(self, a: Array, axis: int | tuple[int, ...]) -> Array:
        return np.amax(a, axis=axis)

    def stack(self, arrays: Sequence[Array], axis: int) -> Array:
        return np.stack(arrays, axis=axis)

    def concat(self, arrays: Sequence[Array], axis: int) -> Array:
        return np.concatenate(arrays, axis=axis)

    def zeros(self, shape: tuple[int, ...], like: Array) -> Array:
        return np.zeros(shape, dtype=like.dtype)

    def ones(self, shape: tuple[int, ...], like: Array) -> Array:
        return np.ones(shape, dtype=like.dtype)

    def eye(self, n: int, like: Array) -> Array:
        return np.eye(n, dtype=like.dtype)

    def array(self, values: Sequence[float], like: Array) -> Array:
        """A 1-D array of ``values`` in the dtype (and on the device) of ``like``."""
        return np.asarray(values, dtype=like.dtype)

    def astype(self, a: Array, like: Array) -> Array:
        """``a`` in the floating dtype of ``like``."""
        return np.asarray(a).astype(like.dtype, copy=False)

    def float32(self, a: Array) -> Array:
        return np.asarray(a, dtype=np.float32)

    def eps(self, a: Array) -> float:
        """Machine epsilon of ``a``'s floating dtype."""
        return float(np.finfo(a.dtype).eps)

    def gather_agents(self, columns: Sequence[Array], index: Array) -> list[Array]:
        """Each agent's neighbours' values: for every column ``(B, N)`` (one value per
        agent), ``out[b, i, s] = column[b, index[b, i, s]]`` ``(B, N, k)``.

        numpy reads all columns in one fancy-indexing pass over a ``(B, N, C)`` table.
        """
        table = np.stack(columns, axis=-1)
        rows = np.arange(table.shape[0])[:, None, None]
        gathered = table[rows, index]
        return [gathered[..., c] for c in range(len(columns))]


class TorchNamespace(ArrayNamespace):
    """torch's operations under the names of :class:`ArrayNamespace` (traceable by
    ``torch.compile``)."""

    name = "torch"

    def __init__(self) -> None:
        import torch

        self.torch = torch

    def potential_decay(self, rho: Array, length: float) -> Array:
        # The pair energy's exponentials evaluated anew, written unlike the force's
        # ``exp(ρ · (−1/l))`` so that TorchInductor does not merge the two: it then sums
        # the energy inside the force's loop, where sharing them made it store both
        # (B, N, N) exponentials and read them back in a second loop.
        return self.torch.exp(rho / (-length))

    def exp(self, a: Array) -> Array:
        return self.torch.exp(a)

    def maximum(self, a: Array, b: Array) -> Array:
        return self.torch.maximum(a, b)

    def exp_temp(self, a: Array) -> Array:
        return self.torch.exp(a)

    def sqrt(self, a: Array) -> Array:
        return self.torch.sqrt(a)

    def sqrt_temp(self, a: Array) -> Array:
        return self.torch.sqrt(a)

    def reciprocal_temp(self, a: Array) -> Array:
        return 1.0 / a

    def abs(self, a: Array) -> Array:
        return self.torch.abs(a)

    def where(self, cond: Array, a: Array, b: Array) -> Array:
        return self.torch.where(cond, a, b)

    def clip(self, a: Array, low: float | None = None, high: float | None = None) -> Array:
        return self.torch.clamp(a, min=low, max=high)

    def sum(self, a: Array, axis: int | tuple[int, ...]) -> Array:
        return self.torch.sum(a, dim=axis)

    def mean(self, a: Array, axis: int | tuple[int, ...]) -> Array:
        return self.torch.mean(a, dim=axis)

    def sum_product(self, a: Array, b: Array) -> Array:
        return self.torch.sum(a * b, dim=-1)

    def amax(self, a: Array, axis: int | tuple[int, ...]) -> Array:
        return self.torch.amax(a, dim=axis)

    def stack(self, arrays: Sequence[Array], axis: int) -> Array:
        return self.torch.stack(list(arrays), dim=axis)

    def concat(self, arrays: Sequence[Array], axis: int) -> Array:
        return self.torch.cat(list(arrays), dim=axis)

    def zeros(self, shape: tuple[int, ...], like: Array) -> Array:
        return self.torch.zeros(shape, dtype=like.dtype, device=like.device)

    def ones(self, shape: tuple[int, ...], like: Array) -> Array:
        return self.torch.ones(shape, dtype=like.dtype, device=like.device)

    def eye(self, n: int, like: Array) -> Array:
        return self.torch.eye(n, dtype=like.dtype, device=like.device)

    def array(self, values: Sequence[float], like: Array) -> Array:
        return self.torch.tensor(values, dtype=like.dtype, device=like.device)

    def astype(self, a: Array, like: Array) -> Array:
        return a.to(like.dtype)

    def float32(self, a: Array) -> Array:
        return a.to(self.torch.float32)

    def eps(self, a: Array) -> float:
        return float(self.torch.finfo(a.dtype).eps)

    def gather_agents(self, columns: Sequence[Array], index: Array) -> list[Array]:
        # Column by column, a gather along the agents of a broadcast view (no copy):
        # TorchInductor fuses each into the loop that consumes it, where one gather of a
        # (B, N, C) table followed by per-feature arithmetic is not vectorised.
        B, N = index.shape[0], index.shape[1]
        return [self.torch.gather(col[:, None, :].expand(B, N, N), 2, index) for col in columns]

    def sum_agents(self, a: Array) -> Array:
        # Component by component: TorchInductor fuses a reduction over the innermost
        # axis, not one over the agents with the components after them.
        return self.torch.stack([a[..., k].sum(-1) for k in range(a.shape[-1])], dim=-1)

    def mean_agents(self, a: Array) -> Array:
        return self.sum_agents(a) / a.shape[-2]


class ScalarNamespace(ArrayNamespace):
    """Plain Python floats, for one swarm's per-swarm terms (the reward of a single env
    costs microseconds instead of a few dozen array operations)."""

    name = "scalar"

    def exp(self, a: Array) -> Array:
        return math.exp(a)

    exp_temp = exp

    def sqrt(self, a: Array) -> Array:
        return math.sqrt(a)

    sqrt_temp = sqrt

    def reciprocal_temp(self, a: Array) -> Array:
        return 1.0 / a

    def abs(self, a: Array) -> Array:
        return abs(a)

    def where(self, cond: Array, a: Array, b: Array) -> Array:
        return a if cond else b

    def clip(self, a: Array, low: float | None = None, high: float | None = None) -> Array:
        if low is not None and a < low:
            return low
        if high is not None and a > high:
            return high
        return a


#: The numpy namespace.
NUMPY = ArrayNamespace()
#: The plain-float namespace (scalars only: no reductions, stacking or gathers).
SCALAR = ScalarNamespace()
_TORCH: list[TorchNamespace] = []


def torch_namespace() -> TorchNamespace:
    """The torch namespace (imports torch on first use)."""
    if not _TORCH:
        _TORCH.append(TorchNamespace())
    return _TORCH[0]


def namespace(*arrays: Array) -> ArrayNamespace:
    """The namespace of ``arrays``: torch's if any is a torch tensor, else numpy's."""
    for a in arrays:
        if type(a).__module__.startswith("torch"):
            return torch_namespace()
    return NUMPY
