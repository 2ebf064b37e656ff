"""Calling a compiled graph directly, without TorchDynamo's per-call guards.

TorchDynamo runs a function compiled by ``torch.compile`` by checking its guards at
every call (the arguments' shapes, dtypes and strides, the module objects the function
read, torch's global state) and then calling the compiled graph. For a core's step, the
checks cost more than the compiled code on small batches, and they can never fail: the
core builds every argument itself, always of the same kinds. So
:class:`~swarm_envs._runtime.torch_compile.MaybeCompiled` with ``direct=True`` compiles
through :func:`graphs_run` (TorchInductor, noting which graph each call through Dynamo
ran), makes its first call through Dynamo (the guards run then, so a changed library
function is seen by the next core built) and from then on calls the noted graph itself
(:class:`DirectCall`).
"""

from __future__ import annotations

import inspect
import operator
import re
import threading
import warnings
from collections.abc import Callable
from typing import Any

import torch
import torch.utils._pytree as pytree

__all__ = ["NOTED", "DirectCall", "graphs_run", "warn_not_direct"]


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


_NOT_DIRECT: set[str] = set()


def warn_not_direct(name: str, why: str) -> None:
    """Warn once per function name that its calls go through TorchDynamo after all."""
    if name in _NOT_DIRECT:
        return
    _NOT_DIRECT.add(name)
    warnings.warn(
        f"{name}: the compiled graph is called through TorchDynamo's guards ({why}); "
        "slower per call, same results",
        UserWarning,
        stacklevel=4,
    )


_PARAMETER = re.compile(r"L\['(\w+)'\]")


class DirectCall:
    """A compiled graph called with the arguments of the function it was traced from.

    TorchDynamo runs a compiled function by checking its guards (the arguments' shapes,
    dtypes and strides, the module objects it read, torch's global state), then calling
    the graph with the tensors it reads, in the graph's order, and putting the graph's
    outputs back into the function's return structure. :meth:`of` builds that mapping
    once and checks it: on the call that was made through Dynamo and on a call with
    random values of the same kinds, the graph alone must give Dynamo's results exactly.
    Calling the instance with a tuple of arguments of the same kinds then runs the graph
    alone.
    """

    def __init__(
        self, graph: Callable[..., Any], order: tuple[int, ...], arity: int, spec: Any
    ) -> None:
        self._graph = graph
        self._pick = operator.itemgetter(*order)
        self._single = len(order) == 1
        self._spec = spec  # None: the outputs are returned as the graph gives them
        self.arity = arity

    def __call__(self, args: tuple[Any, ...]) -> Any:
        picked = self._pick(args)
        out = self._graph(picked) if self._single else self._graph(*picked)
        return out if self._spec is None else pytree.tree_unflatten(list(out), self._spec)

    @classmethod
    def of(
        cls,
        noted: tuple[Callable[..., Any], tuple[str, ...]] | None,
        fn: Callable[..., Any],
        through: Callable[..., Any],
        args: tuple[Any, ...],
        out: Any,
    ) -> tuple[DirectCall | None, str]:
        """The direct call of the graph ``noted`` for calls like ``fn(*args)``, which
        returned ``out`` through TorchDynamo (``through``: ``fn`` compiled); or ``(None,
        why not)``."""
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
        direct = cls(graph, tuple(order), len(args), None if flat else spec)
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
