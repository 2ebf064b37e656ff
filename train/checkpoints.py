"""Checkpoints of an SB3 run that resume it where it stopped.

A checkpoint is a folder ``<out>/checkpoints/step_<timesteps, 12 digits>/`` holding:

* ``model.zip``: SB3's save: the networks, the optimizer state, the step count, the
  last observations and episode starts;
* ``replay_buffer.pkl``: the replay buffer (off-policy algorithms: SAC);
* ``env.pkl``: the training VecEnv itself, pickled: the swarms' states, the episode
  counters and the env's random generator, so episodes continue mid-way;
* ``rng.pkl``: the generators SB3 draws from (Python's ``random``, numpy's global
  generator, torch's CPU and CUDA generators, the action space's generator);
* ``state.json``: the step count, the training seconds so far and the periodic
  evaluation's state (history, best return, next evaluation).

Checkpoints are taken between updates (at the start of a rollout), where the whole
training state is in the objects above: PPO's rollout buffer is empty there, and SAC
has stored its last transition. A checkpoint is written into a hidden folder and renamed
into place once complete, so a run killed while saving leaves the previous checkpoint
intact; :func:`list_checkpoints` ignores the unfinished one.
"""

from __future__ import annotations

import inspect
import json
import os
import pickle
import random
import shutil
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from stable_baselines3.common.base_class import BaseAlgorithm

CHECKPOINTS = "checkpoints"
PREFIX = "step_"
PARTIAL = ".partial-"


def checkpoint_dir(out: Path, timesteps: int) -> Path:
    """Where the checkpoint at ``timesteps`` of the run in ``out`` lives."""
    return Path(out) / CHECKPOINTS / f"{PREFIX}{timesteps:012d}"


def checkpoint_timesteps(path: Path) -> int:
    """The step count in a checkpoint folder's name."""
    return int(path.name[len(PREFIX) :])


def list_checkpoints(out: str | Path) -> list[Path]:
    """The complete checkpoints of the run in ``out``, oldest first."""
    folder = Path(out) / CHECKPOINTS
    if not folder.is_dir():
        return []
    found = [
        p
        for p in folder.iterdir()
        if p.is_dir()
        and p.name.startswith(PREFIX)
        and p.name[len(PREFIX) :].isdigit()
        and (p / "state.json").is_file()
    ]
    return sorted(found, key=checkpoint_timesteps)


def latest_checkpoint(out: str | Path) -> Path | None:
    """The newest complete checkpoint of the run in ``out``, or None."""
    found = list_checkpoints(out)
    return found[-1] if found else None


def write_atomic(path: Path, data: bytes | str) -> None:
    """Write ``path`` through a temporary file renamed into place."""
    tmp = path.with_name(f".{path.name}.tmp")
    if isinstance(data, str):
        tmp.write_text(data, encoding="utf-8")
    else:
        tmp.write_bytes(data)
    os.replace(tmp, path)


def copy_atomic(src: Path, dst: Path) -> None:
    """Copy ``src`` to ``dst`` through a temporary file renamed into place."""
    tmp = dst.with_name(f".{dst.name}.tmp")
    shutil.copyfile(src, tmp)
    os.replace(tmp, dst)


def capture_rng(model: Any) -> dict[str, Any]:
    """The states of every generator SB3 draws from during training."""
    import torch

    state: dict[str, Any] = {
        "python": random.getstate(),
        "numpy": np.random.get_state(),  # noqa: NPY002 (SB3 draws from the global one)
        "torch": torch.get_rng_state(),
        "action_space": getattr(model.action_space, "_np_random", None),
    }
    if model.device.type == "cuda":
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def restore_rng(model: Any, state: dict[str, Any]) -> None:
    """Put back the generators' states that :func:`capture_rng` took."""
    import torch

    random.setstate(state["python"])
    np.random.set_state(state["numpy"])  # noqa: NPY002
    torch.set_rng_state(state["torch"])
    if "cuda" in state and model.device.type == "cuda":
        torch.cuda.set_rng_state_all(state["cuda"])
    if state.get("action_space") is not None:
        model.action_space._np_random = state["action_space"]


def save_checkpoint(model: Any, out: Path, extra: dict[str, Any], keep: int) -> Path:
    """Save the training state of ``model`` into ``out/checkpoints``; keep the ``keep`` newest.

    ``extra`` goes into ``state.json`` beside the step count. Returns the folder. Call it
    between updates only (see the module docstring).
    """
    timesteps = int(model.num_timesteps)
    final = checkpoint_dir(out, timesteps)
    if (final / "state.json").is_file():  # already saved at this step
        return final

    def fill(tmp: Path) -> None:
        model.save(tmp / "model.zip")
        if hasattr(model, "save_replay_buffer") and model.replay_buffer is not None:
            model.save_replay_buffer(tmp / "replay_buffer.pkl")
        env_saved = _save_env(model.get_env(), tmp / "env.pkl")
        with (tmp / "rng.pkl").open("wb") as fh:
            pickle.dump(capture_rng(model), fh, protocol=pickle.HIGHEST_PROTOCOL)
        state = {"timesteps": timesteps, "env_state": env_saved, **extra}
        (tmp / "state.json").write_text(json.dumps(state, indent=2) + "\n")

    return write_checkpoint(out, timesteps, fill, keep)


def write_checkpoint(out: Path, timesteps: int, fill: Callable[[Path], None], keep: int) -> Path:
    """The checkpoint folder of ``timesteps`` in ``out``, written whole or not at all:
    ``fill`` writes its files into a hidden folder, which is then renamed into place
    (replacing a folder of that name); the ``keep`` newest checkpoints are kept."""
    final = checkpoint_dir(out, timesteps)
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = final.with_name(PARTIAL + final.name)
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir()
    fill(tmp)
    if final.exists():  # an incomplete folder of that name, or one being replaced
        shutil.rmtree(final)
    os.replace(tmp, final)
    _prune(out, keep)
    return final


def _wrappers(env: Any) -> list[Any]:
    """``env`` and the SB3 VecEnv wrappers under it, outermost first."""
    chain = [env]
    while "venv" in vars(chain[-1]):  # not getattr: a wrapper forwards unknown names
        chain.append(vars(chain[-1])["venv"])
    return chain


def _save_env(env: Any, path: Path) -> bool:
    """Pickle the training env to ``path``; False (and a warning) if it does not pickle.

    SB3's VecEnv wrappers forward unknown attributes to the env they wrap, through a
    table of their class's members that does not pickle; each wrapper is saved as its
    class and its other attributes, and :func:`_load_env` rebuilds it.
    """
    chain = _wrappers(env)
    layers = [
        (type(w), {k: v for k, v in vars(w).items() if k not in ("venv", "class_attributes")})
        for w in chain[:-1]
    ]
    try:
        data = pickle.dumps((layers, chain[-1]), protocol=pickle.HIGHEST_PROTOCOL)
    except Exception as err:  # any object inside may refuse: resume then resets the env
        warnings.warn(
            f"the training env does not pickle ({err}); a resumed run starts new episodes",
            stacklevel=3,
        )
        return False
    path.write_bytes(data)
    return True


def _load_env(path: Path) -> Any:
    """The env that :func:`_save_env` pickled, wrappers included."""
    with path.open("rb") as fh:
        layers, env = pickle.load(fh)
    for cls, attributes in reversed(layers):
        wrapper = cls.__new__(cls)
        vars(wrapper).update(attributes, venv=env)
        wrapper.class_attributes = dict(inspect.getmembers(cls))
        env = wrapper
    return env


def _prune(out: Path, keep: int) -> None:
    for old in list_checkpoints(out)[:-keep]:
        shutil.rmtree(old, ignore_errors=True)
    for partial in (Path(out) / CHECKPOINTS).glob(PARTIAL + "*"):
        shutil.rmtree(partial, ignore_errors=True)


def load_checkpoint(
    path: Path,
    cls: type[BaseAlgorithm],
    *,
    device: str,
    make_env: Callable[[], Any],
    tensorboard_log: str | None = None,
) -> tuple[Any, dict[str, Any]]:
    """The model of the checkpoint at ``path``, ready to continue learning, and its state.

    The env comes back from ``env.pkl`` when it was saved (episodes continue); otherwise
    ``make_env()`` builds a new one, which SB3 resets before training. The generators
    are restored last, after SB3's loading has seeded them.
    """
    state = json.loads((path / "state.json").read_text())
    env_file = path / "env.pkl"
    if state.get("env_state") and env_file.is_file():
        env, restored = _load_env(env_file), True
    else:
        env, restored = make_env(), False
    model = cls.load(path / "model.zip", env=None, device=device, tensorboard_log=tensorboard_log)
    model.set_env(env, force_reset=not restored)
    from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm

    if isinstance(model, OffPolicyAlgorithm) and (path / "replay_buffer.pkl").is_file():
        model.load_replay_buffer(path / "replay_buffer.pkl")
    with (path / "rng.pkl").open("rb") as fh:
        restore_rng(model, pickle.load(fh))
    return model, state
