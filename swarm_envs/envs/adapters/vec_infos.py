"""The infos of :class:`~swarm_envs.envs.adapters.vec_env.SwarmNavVecEnv`: views, recycled.

At 1,024 swarms × 32 agents a step has 32,768 slots, and SB3 wants an info mapping per
slot. Fresh dicts would cost more than the step itself, and not only to build: every
tracked object a step leaves alive feeds the garbage collector, whose full passes over a
process that imported torch take tens of milliseconds. So:

- :class:`QuietInfo`: the info of a slot with nothing to report, empty and writable:
  one object per slot, made once and reused until something is written to it
  (:class:`QuietInfos` then gives that slot a fresh one from the next step on);
- :class:`SwarmInfo`: the statistics of a swarm, in the info of its first slot, read on
  access from the step's ``(B,)`` arrays; writable;
- :class:`TerminalInfo`: the info of a slot whose swarm just ended (the terminal
  observation, ``TimeLimit.truncated``, ``episode``), read on access from one record of
  that step; writable (SB3's ``VecNormalize`` rewrites ``terminal_observation``).

Both kinds are recycled by pools (:class:`SwarmInfoPool`, :class:`TerminalInfoPool`): a
step reuses a set of objects that nothing outside the pool still references, so an info
kept by the caller keeps its own step's values. A write to either copies the info into a
dict of its own first (the step's arrays are never written).

Every info is a ``dict`` (a subclass): ``isinstance(info, dict)`` holds and
``json.dumps`` takes it. A statistics or terminal info holds its keys as a dict does and
reads each value from the step's arrays on access (``info[key]``, ``get``, ``items``,
``values``, iteration and ``dict(info)`` all see the values; the keys never change
within a VecEnv). Copies are plain dicts: ``dict(info)``, ``info.copy()``, ``copy.copy``
and ``copy.deepcopy`` of an info give a ``dict``, and an info pickles as one. The step's
list of infos is an :class:`InfoList`, a ``list`` whose ``copy.deepcopy`` and pickle give
a plain list with a dict of its own per slot.
"""

from __future__ import annotations

import copy
import sys
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "InfoList",
    "QuietInfo",
    "QuietInfos",
    "SwarmInfo",
    "SwarmInfoPool",
    "TerminalInfo",
    "TerminalInfoPool",
]

#: What ``sys.getrefcount`` says of an object that one list alone holds, measured as the
#: pools measure (interpreters differ in what the count includes).
_FREE_REFCOUNT = max(map(sys.getrefcount, [object()]))


def _free_list_refcount() -> int:
    """What ``sys.getrefcount`` says, in :meth:`QuietInfos.infos`'s loop, of a list that
    the pool alone holds."""
    pool: list[list[Any]] = [[]]
    for held in pool:
        return sys.getrefcount(held)
    raise AssertionError


#: See :func:`_free_list_refcount`.
_FREE_LIST_REFCOUNT = _free_list_refcount()


class _ReadOnAccess(dict):
    """A ``dict`` whose keys are stored and whose values are read on access by
    :meth:`_read`, until something is written: then the values are copied in and it is
    a dict of its own (:attr:`_own`) until its pool reuses it (:meth:`_reuse`).

    Every read goes through :meth:`__getitem__` (``get``, ``items``, ``values``,
    ``copy``, ``==``, ``dict(info)``, ``{**info}``, ``json.dumps``: overriding
    ``__iter__`` sends CPython's dict merge through ``keys()`` and ``__getitem__``), and
    every write through :meth:`_mine` first."""

    __slots__ = ("_own",)
    _own: bool

    def _read(self, key: str) -> Any:  # pragma: no cover - every subclass has one
        raise NotImplementedError

    def _written(self) -> None:
        """Note that this object holds values of its own (its pool resets it)."""

    def _mine(self) -> None:
        if not self._own:
            dict.update(self, [(key, self._read(key)) for key in dict.__iter__(self)])
            self._own = True
            self._written()

    def _reuse(self, keys: Iterable[str]) -> None:
        """Back to reading on access, with ``keys``."""
        dict.clear(self)
        dict.update(self, dict.fromkeys(keys))
        self._own = False

    # reads
    def __getitem__(self, key: str) -> Any:
        if self._own:
            return dict.__getitem__(self, key)
        if not dict.__contains__(self, key):
            raise KeyError(key)
        return self._read(key)

    def get(self, key: str, default: Any = None) -> Any:
        try:
            return self[key]
        except KeyError:
            return default

    def __iter__(self) -> Iterator[str]:
        return dict.__iter__(self)

    def values(self) -> list[Any]:  # type: ignore[override]
        return [self[key] for key in dict.__iter__(self)]

    def items(self) -> list[tuple[str, Any]]:  # type: ignore[override]
        return [(key, self[key]) for key in dict.__iter__(self)]

    def copy(self) -> dict[str, Any]:
        return {key: self[key] for key in dict.__iter__(self)}

    def __copy__(self) -> dict[str, Any]:
        return self.copy()

    def __deepcopy__(self, memo: dict[int, Any]) -> dict[str, Any]:
        return copy.deepcopy(self.copy(), memo)

    def __reduce__(self) -> tuple[type, tuple[dict[str, Any]]]:
        return dict, (self.copy(),)

    def __eq__(self, other: object) -> bool:
        return self.copy() == other if isinstance(other, Mapping) else NotImplemented

    def __ne__(self, other: object) -> bool:
        return self.copy() != other if isinstance(other, Mapping) else NotImplemented

    __hash__ = None

    def __repr__(self) -> str:
        return repr(self.copy())

    def __or__(self, other: Any) -> dict[Any, Any]:
        return self.copy() | other

    def __ror__(self, other: Any) -> dict[Any, Any]:
        return dict(other) | self.copy()

    # writes
    def __setitem__(self, key: str, value: Any) -> None:
        self._mine()
        dict.__setitem__(self, key, value)

    def __delitem__(self, key: str) -> None:
        self._mine()
        dict.__delitem__(self, key)

    def __ior__(self, other: Any) -> _ReadOnAccess:
        self._mine()
        dict.update(self, other)
        return self

    def update(self, *args: Any, **kwargs: Any) -> None:
        self._mine()
        dict.update(self, *args, **kwargs)

    def setdefault(self, key: str, default: Any = None) -> Any:
        self._mine()
        return dict.setdefault(self, key, default)

    def pop(self, key: str, *default: Any) -> Any:
        self._mine()
        return dict.pop(self, key, *default)

    def popitem(self) -> tuple[str, Any]:
        self._mine()
        return dict.popitem(self)

    def clear(self) -> None:
        self._mine()
        dict.clear(self)


class QuietInfo(_ReadOnAccess):
    """The info of a slot with nothing to report: an empty ``dict``, writable.

    One object per slot is made once and reused by every step in which its slot has
    nothing to report, until something is written to it; from the next step on, that
    slot gets a fresh empty object (:class:`QuietInfos`), and the written one keeps what
    was written, in the lists that hold it.
    """

    __slots__ = ("_owner", "_slot")

    def __init__(self, owner: QuietInfos, slot: int) -> None:
        super().__init__()
        self._own = False
        self._owner, self._slot = owner, slot

    def _read(self, key: str) -> Any:  # pragma: no cover - it holds no keys to read
        raise KeyError(key)

    def _written(self) -> None:
        self._owner.written(self._slot)


class QuietInfos:
    """The step's list of infos, starting from every slot's :class:`QuietInfo`.

    One :class:`QuietInfo` per slot, replaced once written (a slot whose object was
    written since the last call gets a fresh one first, so a step's quiet infos are
    always empty when handed out).

    :meth:`infos` hands out an :class:`InfoList` of the current objects. The lists are
    recycled: a list that nothing outside this object references (the caller dropped
    it) and that the caller did not change is reused, with the slots the VecEnv put
    other infos in since (:meth:`InfoList.put`) set back to their quiet objects; else a
    new list is made (a copy of every slot). A step thus touches the slots it writes, not
    every slot. Pickles as its size.

    Args:
        n_slots: the slots of a step (swarms × agents).
    """

    def __init__(self, n_slots: int) -> None:
        self._n = n_slots
        self._current = [QuietInfo(self, i) for i in range(n_slots)]
        self._written: list[int] = []
        self._lists: list[InfoList] = []

    def __reduce__(self) -> tuple[type, tuple[int]]:
        return QuietInfos, (self._n,)

    def written(self, slot: int) -> None:
        """Slot ``slot``'s object was written to: replace it at the next step."""
        self._written.append(slot)

    def infos(self) -> InfoList:
        """A new step's list of infos, every slot's quiet info (empty)."""
        for slot in self._written:
            self._current[slot] = QuietInfo(self, slot)
        if self._written:
            for kept in self._lists:  # they still hold the written objects
                kept._dirty.extend(self._written)
            self._written.clear()
        for infos in self._lists:
            if sys.getrefcount(infos) <= _FREE_LIST_REFCOUNT and not infos._changed:
                dirty = infos._dirty  # held here alone, as the VecEnv left it
                if dirty:
                    current = self._current
                    for where in dirty:
                        list.__setitem__(infos, where, current[where])
                    dirty.clear()
                return infos
        self._lists = [kept for kept in self._lists if not kept._changed]
        infos = InfoList(self._current)
        if len(self._lists) < _MAX_INFO_SETS:
            self._lists.append(infos)
        return infos


def _plain(info: Any) -> Any:
    """A slot's info as a dict of its own (a fresh dict for every mapping)."""
    return dict(info) if isinstance(info, Mapping) else info


class InfoList(list):
    """The list of a step's infos: a ``list`` whose deep copy and pickle are a plain list
    with a plain dict of its own per slot (see the module docstring).

    The VecEnv writes its slots with :meth:`put`, which notes them, so that the list
    can be recycled (:class:`QuietInfos`); any other change to the list (``infos[i] =
    ...``, ``append``, ``sort``, ...) works as on a list and retires it from recycling.
    """

    __slots__ = ("_changed", "_dirty")

    def __init__(self, infos: Iterable[Any] = ()) -> None:
        super().__init__(infos)
        self._dirty: list[int | slice] = []  # the slots put since it was handed out
        self._changed = False  # changed by someone else: never recycled

    def put(self, where: int | slice, value: Any) -> None:
        """``self[where] = value``, noted so that recycling restores the quiet infos."""
        list.__setitem__(self, where, value)
        self._dirty.append(where)

    def __deepcopy__(self, memo: dict[int, Any]) -> list[Any]:
        return [copy.deepcopy(_plain(info), memo) for info in self]

    def __reduce__(self) -> tuple[type, tuple[list[Any]]]:
        return list, ([_plain(info) for info in self],)


def _retiring(name: str) -> Callable[..., Any]:
    """``list``'s method ``name``, marking the list as changed first."""
    method = getattr(list, name)

    def changed(self: InfoList, *args: Any, **kwargs: Any) -> Any:
        self._changed = True
        return method(self, *args, **kwargs)

    changed.__name__ = changed.__qualname__ = name
    changed.__doc__ = method.__doc__
    return changed


for _name in (
    "__setitem__",
    "__delitem__",
    "__iadd__",
    "__imul__",
    "append",
    "extend",
    "insert",
    "pop",
    "remove",
    "clear",
    "sort",
    "reverse",
):
    setattr(InfoList, _name, _retiring(_name))


class SwarmInfo(_ReadOnAccess):
    """The statistics of swarm ``b`` as a ``dict`` ``{key: float}``.

    The info of each swarm's first slot: values are read from one step's ``(B,)``
    arrays on access (``holder[0]``, the step's statistics), so a step builds no dicts.
    Writing or deleting a key first copies the values into the dict itself;
    ``dict(info)``, :meth:`copy` and (deep) copies give a plain dict. The VecEnv reuses
    these objects from step to step while nothing outside it holds them
    (:class:`SwarmInfoPool`).
    """

    __slots__ = ("_b", "_holder")

    def __init__(self, holder: list[Any], b: int) -> None:
        super().__init__(dict.fromkeys(holder[0]))
        self._own = False
        self._holder = holder  # [the step's statistics, dirty list of the set]
        self._b = b

    def _read(self, key: str) -> Any:
        return float(self._holder[0][key][self._b])

    def _written(self) -> None:
        self._holder[1].append(self._b)  # back to reading the arrays when reused

    def __repr__(self) -> str:
        return f"SwarmInfo({self.copy()!r})"


class SwarmInfoPool:
    """The B :class:`SwarmInfo` of a step, recycled once nothing outside holds them.

    Building B fresh objects per step costs little by itself, but at a thousand swarms
    they keep the garbage collector busy (gen-0 passes every step and, as they age, full
    passes over every object of the process). So a step takes a
    set whose objects are referenced by this pool alone (the caller has dropped that
    step's infos) and points it at the new statistics; if every set is still held, it
    makes a new one. An info kept by the caller thus keeps its step's values.
    """

    def __init__(self, n_swarms: int) -> None:
        self.n_swarms = n_swarms
        self._sets: list[tuple[list[Any], list[SwarmInfo]]] = []

    def __reduce__(self) -> tuple[type, tuple[int]]:
        return SwarmInfoPool, (self.n_swarms,)  # pickled without its sets (no step's infos)

    def infos(self, stats: Mapping[str, np.ndarray]) -> list[SwarmInfo]:
        """B infos reading ``stats``: a free recycled set, or a new one.

        The set handed out longest ago is tried first (a caller like SB3's rollout
        loop still holds the last one while it takes the next), so a step usually
        scans one set.
        """
        for n, (holder, objects) in enumerate(self._sets):
            if max(map(sys.getrefcount, objects)) <= _FREE_REFCOUNT:  # the pool's list only
                for b in holder[1]:  # written to since: back to reading the arrays
                    objects[b]._reuse(stats)
                holder[:] = [stats, []]
                self._sets.append(self._sets.pop(n))  # now the newest
                return objects
        holder = [stats, []]
        objects = [SwarmInfo(holder, b) for b in range(self.n_swarms)]
        if len(self._sets) < _MAX_INFO_SETS:
            self._sets.append((holder, objects))
        return objects


#: Recycled sets of SwarmInfo per VecEnv: two cover a caller that keeps one step's infos
#: while it takes the next (SB3's rollout loop); more sets are made fresh, not kept.
_MAX_INFO_SETS = 3


#: The keys of every terminal info, after the statistics in a swarm's first slot.
TERMINAL_KEYS = ("terminal_observation", "TimeLimit.truncated", "episode", "swarm_episode")


@dataclass
class TerminalRecord:
    """What the terminal infos of one step read: the last observations ``(N, obs_dim)``
    of the swarms that ended (before their reset), by swarm; the step's statistics;
    ``TimeLimit.truncated`` per swarm ``(B,)``; and the ``episode`` dicts of the swarms
    that ended, by swarm."""

    obs: Mapping[int, np.ndarray]
    stats: Mapping[str, np.ndarray]
    time_limit: np.ndarray
    episodes: dict[int, dict[str, float]]


class TerminalInfo(_ReadOnAccess):
    """The info of slot ``i`` (agent i) of swarm ``b`` at the step the swarm's episode ended.

    Keys: the swarm's statistics (first slot, ``i == 0``, only), then
    ``terminal_observation`` (the agent's last observation of the episode),
    ``TimeLimit.truncated``, ``episode`` and ``swarm_episode`` (one dict per swarm),
    read on access from the step's :class:`TerminalRecord`. Writing or deleting a key
    first copies the values into the dict itself (as ``VecNormalize`` does to
    ``terminal_observation``); :meth:`copy` and (deep) copies give a plain dict.
    """

    __slots__ = ("_b", "_holder", "_i")

    def __init__(self, holder: list[Any], b: int, i: int) -> None:
        super().__init__()
        self._own = False
        self._holder = holder  # [TerminalRecord, dirty list of the set]
        self._b = b
        self._i = i
        self._reuse(self.keys_of(holder[0]))

    def keys_of(self, record: TerminalRecord | None) -> list[str]:
        """The keys of this slot's info for ``record`` (``None``: before any record)."""
        stats = list(record.stats) if self._i == 0 and record is not None else []
        return [*stats, *TERMINAL_KEYS]

    def _read(self, key: str) -> Any:
        record: TerminalRecord = self._holder[0]
        b = self._b
        if key == "terminal_observation":
            return record.obs[b][self._i]
        if key == "TimeLimit.truncated":
            return bool(record.time_limit[b])
        if key == "episode" or key == "swarm_episode":
            return record.episodes[b]
        return float(record.stats[key][b])

    def _written(self) -> None:
        self._holder[1].append((self._b, self._i))  # reset when the set is reused

    def __repr__(self) -> str:
        return f"TerminalInfo(swarm={self._b}, agent={self._i}, keys={list(self)!r})"


class TerminalInfoPool:
    """The B × N :class:`TerminalInfo` of a step, recycled once nothing outside holds them.

    When every swarm ends at once (all at the step limit), tens of thousands of fresh
    dicts per reset cost tens of milliseconds, and as they age, full garbage-collector
    passes. A
    step takes a set whose objects only this pool references and points it at the new
    :class:`TerminalRecord`; the slots of the swarms that ended get that set's objects.
    A set holds one list of N objects per swarm, so that checking the swarms handed out
    last looks at their objects alone.
    """

    def __init__(self, n_swarms: int, n_agents: int) -> None:
        self.n_swarms, self.n_agents = n_swarms, n_agents
        # (holder, objects by swarm, the swarms whose objects were handed out last)
        self._sets: list[tuple[list[Any], list[list[TerminalInfo]], list[int]]] = []
        # The first set now, not at the first episode end: at 1,024 × 32 making it takes
        # about 0.1 s (with the garbage collector's passes), a hitch in the middle of a
        # rollout otherwise.
        self._sets.append(self._new_set(None, []))

    def __reduce__(self) -> tuple[type, tuple[int, int]]:
        return TerminalInfoPool, (self.n_swarms, self.n_agents)  # pickled without its sets

    def _new_set(
        self, record: TerminalRecord | None, ended: list[int]
    ) -> tuple[list[Any], list[list[TerminalInfo]], list[int]]:
        holder: list[Any] = [record, []]  # [record, the (b, i) written to since]
        N = self.n_agents
        by_swarm = [[TerminalInfo(holder, b, i) for i in range(N)] for b in range(self.n_swarms)]
        return holder, by_swarm, list(ended)

    def infos(self, record: TerminalRecord, ended: list[int]) -> list[list[TerminalInfo]]:
        """The N infos of each swarm (slot b·N + i is ``[b][i]``) reading ``record``, of
        which the caller hands out those of the swarms ``ended``: a free recycled set
        (the one handed out longest ago first), or a new one."""
        for n, (holder, by_swarm, given) in enumerate(self._sets):
            # Only the objects handed out last time can be held outside.
            if all(max(map(sys.getrefcount, by_swarm[b])) <= _FREE_REFCOUNT for b in given):
                for b, i in holder[1]:  # written to since: back to reading the record
                    by_swarm[b][i]._reuse(by_swarm[b][i].keys_of(record))
                holder[:] = [record, []]
                given[:] = ended
                _with_statistics(by_swarm, ended, record)
                self._sets.append(self._sets.pop(n))  # now the newest
                return by_swarm
        new = self._new_set(record, ended)
        if len(self._sets) < _MAX_INFO_SETS:
            self._sets.append(new)
        return new[1]


def _with_statistics(
    by_swarm: list[list[TerminalInfo]], ended: list[int], record: TerminalRecord
) -> None:
    """Give the first slot of each swarm ``ended`` the statistics' keys of ``record``
    (a set made before the first record has none yet; the keys never change after)."""
    size = len(record.stats) + len(TERMINAL_KEYS)
    for b in ended:
        first = by_swarm[b][0]
        if len(first) != size and not first._own:
            first._reuse(first.keys_of(record))
