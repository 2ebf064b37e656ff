"""The import paths users rely on stay, as aliases of where things are defined; the
project's own code imports from the definitions, never through an alias."""

from __future__ import annotations

import ast
import importlib
import warnings
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

#: Alias module -> {name: (defining module, name there)}.
ALIASES = {
    "swarm_envs.envs.core": {"SwarmNavCore": ("swarm_envs.envs.cores.numpy", "SwarmNavCore")},
    "swarm_envs.envs.swarm_nav": {
        "SwarmNavEnv": ("swarm_envs.envs.adapters.swarm_nav", "SwarmNavEnv"),
        "SwarmNavParallelEnv": ("swarm_envs.envs.adapters.swarm_nav", "SwarmNavParallelEnv"),
    },
    "swarm_envs.envs.vec_env": {
        "SwarmNavVecEnv": ("swarm_envs.envs.adapters.vec_env", "SwarmNavVecEnv"),
        "SlotEpisodesWarning": ("swarm_envs.envs.adapters.vec_env", "SlotEpisodesWarning"),
    },
    "swarm_envs.envs.gym_vector": {
        "SwarmNavVectorEnv": ("swarm_envs.envs.adapters.gym_vector", "SwarmNavVectorEnv"),
    },
    "swarm_envs.envs.torch_core": {
        "TorchSwarmNavCore": ("swarm_envs.envs.cores.torch.core", "TorchSwarmNavCore"),
    },
    "swarm_envs.envs.native": {
        name: ("swarm_envs.envs.cores.native", name)
        for name in ("NATIVE_ENV", "NativeSwarmNavCore", "native_support", "resolve_native")
    },
    "swarm_envs.envs.sparse_core": {
        name: ("swarm_envs.envs.cores.cutoff.core", name)
        for name in (
            "CUTOFF_MIN_AGENTS",
            "DEFAULT_CUTOFF_SPEED",
            "DEFAULT_CUTOFF_TOL",
            "CutoffSwarmNavCore",
            "density_preserving_radius",
            "use_cutoff_core",
        )
    },
}

#: The names with ``sparse`` in them: each warns and gives its ``cutoff`` name's object.
SPARSE_NAMES = {
    "SparseSwarmNavCore": "CutoffSwarmNavCore",
    "SPARSE_MIN_AGENTS": "CUTOFF_MIN_AGENTS",
    "use_sparse_core": "use_cutoff_core",
}


@pytest.mark.parametrize("alias", sorted(ALIASES))
def test_an_alias_module_gives_the_defined_objects(alias: str) -> None:
    module = importlib.import_module(alias)
    assert sorted(module.__all__) == sorted(ALIASES[alias])
    for name, (where, defined) in ALIASES[alias].items():
        assert getattr(module, name) is getattr(importlib.import_module(where), defined)


def test_the_sparse_names_warn_and_give_the_cutoff_ones() -> None:
    from swarm_envs.envs import sparse_core
    from swarm_envs.envs.cores.cutoff import core

    for old, new in SPARSE_NAMES.items():
        with pytest.warns(DeprecationWarning, match=f"{old} is deprecated: use {new}"):
            assert getattr(sparse_core, old) is getattr(core, new)
    with pytest.warns(DeprecationWarning):
        from swarm_envs.envs.sparse_core import SparseSwarmNavCore
    assert SparseSwarmNavCore is core.CutoffSwarmNavCore
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        from swarm_envs.envs.sparse_core import CutoffSwarmNavCore  # the new name: quiet
    assert CutoffSwarmNavCore is core.CutoffSwarmNavCore
    with pytest.raises(AttributeError, match="no attribute 'SparseCore'"):
        sparse_core.SparseCore  # noqa: B018


def _imports(path: Path) -> list[tuple[int, str]]:
    """``(line, module)`` of every import in ``path`` (``from a import b``: ``a`` and
    ``a.b``)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.append((node.lineno, node.module))
            found += [(node.lineno, f"{node.module}.{alias.name}") for alias in node.names]
    return found


def test_the_project_imports_no_alias_module() -> None:
    """Internal code (the packages, tests, benchmarks, examples) imports each name from
    the module that defines it; the aliases are for users' code."""
    skip = {Path(__file__).resolve()} | {ROOT / f"{a.replace('.', '/')}.py" for a in ALIASES}
    offenders = []
    for folder in ("swarm_envs", "agents", "train", "tests", "benchmarks", "examples"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            if path in skip:
                continue
            offenders += [
                f"{path.relative_to(ROOT)}:{line} imports {module}"
                for line, module in _imports(path)
                if module in ALIASES
            ]
    assert not offenders, "\n".join(offenders)
