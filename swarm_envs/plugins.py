"""A user's own files, imported before environments are built: their tasks and models.

A plugin is a Python file (``path/to/my_task.py``) or an importable module
(``my_package.my_task``) whose import registers what it defines
(:func:`~swarm_envs.tasks.register_task` for a task). The command-line tools load the
ones named by ``--plugin`` and by the ``plugins:`` list of a train config, before they
read the env config; a script calls :func:`load_plugin` itself (or simply imports its
module).

Each file is imported once per process, as the module ``swarm_envs_plugin_<stem>_<hash>``
(registered in ``sys.modules``, so that what it defines pickles by name within the
process). The paths loaded are also kept in the environment variable
:data:`PLUGINS_ENV`, which ``import swarm_envs`` reads: worker processes started with
``spawn`` or ``forkserver`` load the same plugins before they unpickle an environment.

>>> load_plugin("no/such/file.py")
Traceback (most recent call last):
...
ValueError: plugin file not found: no/such/file.py
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import os
import sys
from collections.abc import Iterable
from pathlib import Path
from types import ModuleType

__all__ = ["PLUGINS_ENV", "load_plugin", "load_plugins", "load_plugins_from_environment"]

#: The environment variable listing the plugins loaded (``os.pathsep``-separated).
PLUGINS_ENV = "SWARM_ENVS_PLUGINS"

_LOADED: dict[str, ModuleType] = {}


def _is_file_reference(ref: str) -> bool:
    return ref.endswith(".py") or os.sep in ref or (os.altsep is not None and os.altsep in ref)


def _resolve(ref: str, base: Path | None) -> Path:
    candidates = [Path(ref)]
    if base is not None and not Path(ref).is_absolute():
        candidates.append(base / ref)
    for path in candidates:
        if path.is_file():
            return path.resolve()
    where = "" if base is None else f" (looked in . and {base})"
    raise ValueError(f"plugin file not found: {ref}{where}")


def _remember(key: str) -> None:
    known = [p for p in os.environ.get(PLUGINS_ENV, "").split(os.pathsep) if p]
    if key not in known:
        os.environ[PLUGINS_ENV] = os.pathsep.join([*known, key])


def load_plugin(ref: str | Path, base: str | Path | None = None) -> ModuleType:
    """Import the plugin ``ref``: a ``.py`` file (a path, relative to the working folder
    or else to ``base``) or a module name; returns the module (imported once).

    Raises:
        ValueError: the file or module does not exist, or importing it failed (the
            message names the plugin and the error; the original is chained).
    """
    text = str(ref)
    if not text.strip():
        raise ValueError("a plugin must be a .py file or a module name, got ''")
    if _is_file_reference(text) or isinstance(ref, Path):
        path = _resolve(text, None if base is None else Path(base))
        key = str(path)
        if key in _LOADED:
            return _LOADED[key]
        digest = hashlib.sha1(key.encode()).hexdigest()[:8]
        name = f"swarm_envs_plugin_{path.stem}_{digest}"
        spec = importlib.util.spec_from_file_location(name, path)
        if spec is None or spec.loader is None:
            raise ValueError(f"plugin {path}: not a Python file")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        try:
            spec.loader.exec_module(module)
        except Exception as err:
            del sys.modules[name]
            raise ValueError(f"plugin {path} failed to load: {type(err).__name__}: {err}") from err
    else:
        key = text
        if key in _LOADED:
            return _LOADED[key]
        try:
            module = importlib.import_module(text)
        except ModuleNotFoundError as err:
            if err.name is not None and text.startswith(err.name):
                raise ValueError(
                    f"plugin module not found: {text} (a file needs its .py ending)"
                ) from None
            raise ValueError(f"plugin {text} failed to load: ModuleNotFoundError: {err}") from err
        except Exception as err:
            raise ValueError(f"plugin {text} failed to load: {type(err).__name__}: {err}") from err
    _LOADED[key] = module
    _remember(key)
    return module


def load_plugins(refs: Iterable[str | Path], base: str | Path | None = None) -> list[ModuleType]:
    """:func:`load_plugin` for each of ``refs``, in order."""
    return [load_plugin(ref, base) for ref in refs]


def load_plugins_from_environment() -> list[ModuleType]:
    """Load the plugins :data:`PLUGINS_ENV` lists (absolute paths or module names);
    ``import swarm_envs`` calls this, so that a worker process has them too."""
    refs = [p for p in os.environ.get(PLUGINS_ENV, "").split(os.pathsep) if p]
    return load_plugins(refs)
