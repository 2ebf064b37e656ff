"""Checking what a compiled function reads from modules once per core, not once per call.

TorchDynamo guards every call of a compiled function: its tensor arguments (shape,
dtype, device, strides, aliasing), torch's global state, and every module-level object
the traced code read (the functions it inlined, module constants, ``torch.exp`` ...).
A core's step reads hundreds of such objects, and checking them costs a good part of a
small step's time; yet they change only if someone replaces a library function at run
time (as tests do, to show that a broken term is caught).

:class:`ModuleGuards` moves those checks to the construction of a core:
:meth:`ModuleGuards.filter` is the ``guard_filter_fn`` of ``torch.compile``. It keeps
every guard on the call's own arguments and closure, and torch's global state, and drops
the guards on module-level objects (Dynamo names them ``G[...]``), noting each object it
dropped a guard on. :meth:`ModuleGuards.unchanged` later says whether every noted object
is still the one that was compiled against; :func:`swarm_envs._runtime.torch_compile.
MaybeCompiled` shares a compiled function between cores only while it is, and compiles
anew otherwise.

>>> import math
>>> guards = ModuleGuards({"math": math})
>>> guards.note("G['math'].pi")
>>> guards.unchanged()
True
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Any

__all__ = ["ModuleGuards"]

#: Guards on torch's global state: kept, as ``is_global`` guards on module objects are
#: not (these have ``is_global`` false, but are listed to be explicit).
_GLOBAL_STATE = frozenset(
    {
        "GLOBAL_STATE",
        "GRAD_MODE",
        "DETERMINISTIC_ALGORITHMS",
        "TORCH_FUNCTION_STATE",
        "DEFAULT_DEVICE",
        "SHAPE_ENV",
        "AUTOGRAD_SAVED_TENSORS_HOOKS",
    }
)

#: ``G['name']`` at the start of a guard's source, then attribute and item accesses.
_ROOT = re.compile(r"G\['(\w+)'\]")
_ACCESS = re.compile(r"\.(\w+)|\[(\d+)\]|\['(\w+)'\]")


def _path(source: str) -> tuple[str, tuple[tuple[str, str | int], ...]] | None:
    """The global and the accesses that a guard's source names, up to the first part
    this parser does not read or a dunder attribute (``None``: no global in it).

    ``"G['m'].f[0].g"`` → ``("m", (("attr", "f"), ("item", 0), ("attr", "g")))``.
    """
    root = _ROOT.search(source)
    if root is None:
        return None
    steps: list[tuple[str, str | int]] = []
    at = root.end()
    while (access := _ACCESS.match(source, at)) is not None:
        attr, index, key = access.groups()
        if attr is not None and attr.startswith("__"):
            break  # ``__dict__``, ``__mro__``: a new object at each access
        if attr is not None:
            steps.append(("attr", attr))
        elif index is not None:
            steps.append(("item", int(index)))
        else:
            steps.append(("item", key))
        at = access.end()
    return root.group(1), tuple(steps)


_MISSING = object()


def _resolve(scope: dict[str, Any], path: tuple[str, tuple[tuple[str, str | int], ...]]) -> Any:
    """The object at ``path`` in ``scope`` (a function's globals), or a marker that
    matches nothing when it is not there any more."""
    name, steps = path
    obj = scope.get(name, _MISSING)
    for kind, what in steps:
        if obj is _MISSING:
            break
        try:
            obj = getattr(obj, what) if kind == "attr" else obj[what]  # type: ignore[arg-type,index]
        except (AttributeError, LookupError, TypeError):
            return _MISSING
    return obj


class ModuleGuards:
    """The module-level objects a compiled function was traced against, checked on demand.

    Args:
        scope: the globals of the compiled function (where Dynamo also installs its
            aliases of the modules it inlined from, ``__import_...``).
    """

    def __init__(self, scope: dict[str, Any]) -> None:
        self._scope = scope
        #: Each noted path and the object it led to (held, so that its id stays unique).
        self._seen: dict[tuple[str, tuple[tuple[str, str | int], ...]], Any] = {}
        #: Whether a dropped guard named something this class cannot check.
        self.unreadable = False

    def note(self, source: str) -> None:
        """Note the object that ``source`` (a guard's name) leads to now."""
        path = _path(source)
        if path is None:
            self.unreadable = True
            return
        if path not in self._seen:
            self._seen[path] = _resolve(self._scope, path)

    def filter(self, entries: Sequence[Any]) -> list[bool]:
        """``torch.compile``'s ``guard_filter_fn``: keep the guards on the arguments,
        the closure and torch's global state; note and drop those on module objects."""
        keep = []
        for entry in entries:
            if entry.is_global and entry.guard_type not in _GLOBAL_STATE:
                self.note(entry.name)
                keep.append(False)
            else:
                keep.append(True)
        return keep

    def unchanged(self) -> bool:
        """Whether every noted object is still the one found when it was noted (and
        every dropped guard could be noted)."""
        if self.unreadable:
            return False
        scope = self._scope
        return all(_resolve(scope, path) is obj for path, obj in self._seen.items())
