"""Calling a compiled graph directly, without TorchDynamo's per-call guards.

TorchDynamo runs a function compiled by ``torch.compile`` by checking its guards at
every call (the arguments' shapes, dtypes and strides, the module objects the function
read, torch's global state) and then calling the compiled graph. For a core's step, the
checks cost more than the compiled code on small batches: the core builds every argument
itself, always of the same kinds. So
:class:`~swarm_envs._runtime.torch_compile.MaybeCompiled` with ``direct=True`` compiles
through :func:`graphs_run` (TorchInductor, noting which graph each call through Dynamo
ran), makes its first call through Dynamo (the guards run then, so a changed library
function is seen by the next core built) and from then on calls the noted graph itself
(:class:`DirectCall`).

What the graph was traced for and a later argument can still differ in, the direct call
checks at every call, at a small part of the guards' cost: each tensor's shape, strides,
dtype and device (its *layout*). The graph reads its inputs at the strides it was traced
for, so a tensor laid out otherwise (a permuted view, the result of an operation that
kept another input's layout) is copied into the traced layout first, with a warning
once per function (the caller should build it so); a tensor of another shape, dtype or
device is passed to TorchDynamo, whose guards compile the function again for it (a
warning once too).
"""

from __future__ import annotations

import inspect
import operator
import re
import threading
import warnings
from collections.abc import Callable
from typing import Any, NamedTuple

import torch
import torch.utils._pytree as pytree

__all__ = ["NOTED", "DirectCall", "Layout", "graphs_run", "warn_not_direct"]


class _GraphsRun:
    """A ``torch.compile`` backend: TorchInductor with ``options``, noting in
    :data:`NOTED` the graph that each call through TorchDynamo runs (the compiled graph
    and the source of each of its inputs, such as ``"L['x']"``). One instance per set
    of options (:func:`graphs_run`), so that TorchDynamo shares compiled graphs between
    the functions that use it, as it does for ``torch.compile``'s own backend."""

    def __init__(self, options: dict[str, Any] | None) -> None:
        self.options = options

    def __call__(self, gm: torch.fx.GraphModule, example_inputs: list[Any]) -> Callable[..., Any]:
        from torch._inductor import compile as inductor_compile

        compiled = inductor_compile(gm, example_inputs, options=self.options)
        try:
            sources = tuple(
                str(node.meta["grapharg"].source.name)
                for node in gm.graph.find_nodes(op="placeholder")
            )
        except (AttributeError, KeyError):  # pragma: no cover - depends on the torch version
            sources = ()
        noted = (compiled, sources)

        def run(*inputs: Any) -> Any:
            NOTED.last = noted
            return compiled(*inputs)

        return run


#: The graph that the last call through TorchDynamo ran in this thread (``last``).
NOTED = threading.local()
_GRAPHS_RUN: dict[tuple[tuple[str, Any], ...], _GraphsRun] = {}


def graphs_run(options: dict[str, Any] | None) -> _GraphsRun:
    """The :class:`_GraphsRun` backend for ``options`` (one per distinct set)."""
    key = tuple(sorted((options or {}).items()))
    if key not in _GRAPHS_RUN:
        _GRAPHS_RUN[key] = _GraphsRun(dict(options or {}))
    return _GRAPHS_RUN[key]


_WARNED: set[tuple[str, str]] = set()


def _warn_once(name: str, kind: str, message: str) -> None:
    """Warn ``message`` once per function name and ``kind`` of warning."""
    if (name, kind) in _WARNED:
        return
    _WARNED.add((name, kind))
    warnings.warn(message, UserWarning, stacklevel=5)


def warn_not_direct(name: str, why: str) -> None:
    """Warn once per function name that its calls go through TorchDynamo after all."""
    _warn_once(
        name,
        "guarded",
        f"{name}: the compiled graph is called through TorchDynamo's guards ({why}); "
        "slower per call, same results",
    )


class Layout(NamedTuple):
    """What a compiled graph assumes of a tensor input: shape, strides, dtype, device."""

    shape: torch.Size
    stride: tuple[int, ...]
    dtype: torch.dtype
    device: torch.device

    @classmethod
    def of(cls, t: torch.Tensor) -> Layout:
        return cls(t.shape, t.stride(), t.dtype, t.device)

    def strides_fit(self, t: torch.Tensor) -> bool:
        """Whether ``t`` (of this shape) is read correctly at these strides: equal
        strides on every axis longer than 1 (TorchInductor's own check)."""
        return all(
            n < 2 or a == b for n, a, b in zip(self.shape, self.stride, t.stride(), strict=True)
        )

    def like(self, t: torch.Tensor) -> torch.Tensor:
        """A copy of ``t`` (of this shape, dtype and device) at these strides."""
        out = torch.empty_strided(self.shape, self.stride, dtype=self.dtype, device=self.device)
        return out.copy_(t)


_PARAMETER = re.compile(r"L\['(\w+)'\]")


class DirectCall:
    """A compiled graph called with the arguments of the function it was traced from.

    TorchDynamo runs a compiled function by checking its guards (the arguments' shapes,
    dtypes and strides, the module objects it read, torch's global state), then calling
    the graph with the tensors it reads, in the graph's order, and putting the graph's
    outputs back into the function's return structure. :meth:`of` builds that mapping
    once and checks it: on the call that was made through Dynamo and on a call with
    random values of the same kinds, the graph alone must give Dynamo's results exactly.
    Calling the instance with a tuple of arguments runs the graph alone, after checking
    each tensor's layout against the traced one (module docstring): a tensor at other
    strides is copied into the traced layout (counted in :attr:`relaid`), one of
    another shape, dtype or device sends the call through ``through`` (Dynamo's guards;
    counted in :attr:`guarded`), each with a warning once per function ``name``.
    """

    def __init__(
        self,
        graph: Callable[..., Any],
        order: tuple[int, ...],
        arity: int,
        spec: Any,
        layouts: tuple[Layout, ...],
        through: Callable[..., Any],
        name: str = "",
        labels: tuple[str, ...] = (),
    ) -> None:
        self._graph = graph
        self._pick = operator.itemgetter(*order)
        self._single = len(order) == 1
        self._spec = spec  # None: the outputs are returned as the graph gives them
        self._layouts = layouts
        self._strides = tuple(layout.stride for layout in layouts)
        self._shapes = tuple(layout.shape for layout in layouts)
        self._kinds = tuple((layout.dtype, layout.device) for layout in layouts)
        self._through = through
        self._labels = labels or tuple(str(i) for i in order)
        self.name = name or getattr(through, "__name__", "function")
        self.arity = arity
        #: Calls that copied a tensor into the traced layout first.
        self.relaid = 0
        #: Calls passed to TorchDynamo (a tensor of another shape, dtype or device).
        self.guarded = 0

    def __call__(self, args: tuple[Any, ...]) -> Any:
        picked = self._pick(args)
        if self._single:
            picked = (picked,)
        try:
            fits = (
                tuple([t.stride() for t in picked]) == self._strides
                and tuple([t.shape for t in picked]) == self._shapes
                and tuple([(t.dtype, t.device) for t in picked]) == self._kinds
            )
        except AttributeError:  # not a tensor
            fits = False
        if not fits:
            fitted = self._fitted(picked)
            if fitted is None:
                return self._through(*args)
            picked = fitted
        out = self._graph(*picked)
        return out if self._spec is None else pytree.tree_unflatten(list(out), self._spec)

    def _fitted(self, picked: tuple[Any, ...]) -> tuple[Any, ...] | None:
        """``picked`` with every tensor in its traced layout (copied where its strides
        differ); ``None`` where one differs in shape, dtype or device (or is no tensor)."""
        fitted = []
        copied = []
        for label, t, layout in zip(self._labels, picked, self._layouts, strict=True):
            if not isinstance(t, torch.Tensor) or (t.shape, t.dtype, t.device) != (
                layout.shape,
                layout.dtype,
                layout.device,
            ):
                self.guarded += 1
                got = Layout.of(t) if isinstance(t, torch.Tensor) else type(t).__name__
                _warn_once(
                    self.name,
                    "guarded",
                    f"{self.name}: argument {label!r} of the compiled graph is {got}, traced as "
                    f"{layout}; calling it through TorchDynamo's guards (it compiles "
                    "again for new shapes, dtypes or devices)",
                )
                return None
            if not layout.strides_fit(t):
                copied.append(f"{label!r} at strides {tuple(t.stride())}, not {layout.stride}")
                t = layout.like(t)
            fitted.append(t)
        if copied:
            self.relaid += 1
            _warn_once(
                self.name,
                "relaid",
                f"{self.name}: the compiled graph is given tensors laid out otherwise than "
                f"it was traced for ({'; '.join(copied)}); copying them into the traced "
                "layout at each such call (slower, same results)",
            )
        return tuple(fitted)

    @classmethod
    def of(
        cls,
        noted: tuple[Callable[..., Any], tuple[str, ...]] | None,
        fn: Callable[..., Any],
        through: Callable[..., Any],
        args: tuple[Any, ...],
        out: Any,
        name: str = "",
    ) -> tuple[DirectCall | None, str]:
        """The direct call of the graph ``noted`` for calls like ``fn(*args)``, which
        returned ``out`` through TorchDynamo (``through``: ``fn`` compiled); or ``(None,
        why not)``. ``name``: the function's name in warnings."""
        if noted is None:
            return None, "no graph noted"
        graph, sources = noted
        names = list(inspect.signature(fn).parameters)[: len(args)]
        order = []
        for source in sources:
            match = _PARAMETER.fullmatch(source)
            if match is None or match.group(1) not in names:
                return None, f"the graph reads {source}, not an argument"
            order.append(names.index(match.group(1)))
        tensors = {i for i, arg in enumerate(args) if isinstance(arg, torch.Tensor)}
        if set(order) != tensors or len(order) != len(tensors):
            return None, "the graph does not read each tensor argument once"
        leaves, spec = pytree.tree_flatten(out)
        if not leaves or not all(isinstance(t, torch.Tensor) for t in leaves):
            return None, "the function returns more than tensors"
        flat = isinstance(out, tuple) and len(out) == len(leaves)
        layouts = tuple(Layout.of(args[i]) for i in order)
        name = name or getattr(fn, "__qualname__", "")
        labels = tuple(names[i] for i in order)
        direct = cls(
            graph, tuple(order), len(args), None if flat else spec, layouts, through, name, labels
        )
        scrambled = _scrambled(args)
        for trial, expected in ((args, out), (scrambled, through(*scrambled))):
            got = pytree.tree_flatten(direct(trial))[0]
            wanted = pytree.tree_flatten(expected)[0]
            if len(got) != len(wanted) or not all(map(_identical, got, wanted)):
                return None, "the graph alone does not give the function's results"
        return direct, ""


def _scrambled(args: tuple[Any, ...]) -> tuple[Any, ...]:
    """Arguments like ``args`` (shapes, strides, dtypes, devices) with random floating
    values (from a generator of their own)."""
    generators: dict[torch.device, torch.Generator] = {}
    scrambled = []
    for arg in args:
        if isinstance(arg, torch.Tensor) and arg.is_floating_point():
            gen = generators.setdefault(arg.device, torch.Generator(arg.device).manual_seed(0))
            values = torch.rand(arg.shape, generator=gen, dtype=arg.dtype, device=arg.device)
            arg = torch.empty_strided(arg.shape, arg.stride(), dtype=arg.dtype, device=arg.device)
            arg.copy_(values)
        scrambled.append(arg)
    return tuple(scrambled)


def _identical(a: Any, b: Any) -> bool:
    """Whether tensors ``a`` and ``b`` have the same shape, dtype, device and values
    (NaN equal)."""
    if not isinstance(a, torch.Tensor) or not isinstance(b, torch.Tensor):
        return False
    if (a.shape, a.dtype, a.device) != (b.shape, b.dtype, b.device):
        return False
    if a.is_floating_point():
        return bool(torch.isclose(a, b, rtol=0.0, atol=0.0, equal_nan=True).all())
    return bool(torch.equal(a, b))
