"""The C step's cache (swarm_envs.envs.cores.native.build): checked before it is loaded.

A damaged cached library (truncated, empty, cut short, garbage, without its record) is
never handed to the loader: it is rebuilt with a warning, or, without a compiler, refused
(``auto`` warns and runs numpy; ``SWARM_ENVS_NATIVE=1`` raises). Every case that could
crash the loader runs in a child process, so a crash fails the test instead of ending
pytest. Also: an intact library loads without any compiler; a hung compiler is killed
after ``SWARM_ENVS_CC_TIMEOUT``; concurrent processes build once; folders of killed
builds are removed; each fallback warns once; each build is announced. The libraries
built at install are ignored here (``SWARM_ENVS_NATIVE_PREBUILT=0``;
tests/test_native_variants.py is about them).

One real build at most (the library of the default cache, reused); rebuilds use a fake
compiler that copies that library, so they take milliseconds.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest

from swarm_envs.config import SwarmConfig
from swarm_envs.envs import backends
from swarm_envs.envs.backends import make_core
from swarm_envs.envs.cores.native import build, native_support

ROOT = Path(__file__).resolve().parents[1]

#: A child process that loads the C step, makes two cores with ``auto`` and prints what
#: happened as JSON (every UserWarning, in order).
PROBE = textwrap.dedent(
    """
    import json, warnings
    ANNOUNCE = "building the C step now"
    from swarm_envs.config import SwarmConfig
    from swarm_envs.envs.backends import make_core
    from swarm_envs.envs.cores.native import build, native_support
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ok, why = native_support()
        cores = [make_core(SwarmConfig(n_agents=4)) for _ in range(2)]
    if ok:
        import numpy as np
        cores[0].reset(np.random.default_rng(0))
        cores[0].step(np.zeros((1, 4, 2)))
    print(json.dumps({
        "ok": ok, "why": why, "backend": cores[0].backend,
        "path": str(build.load_library().path) if ok else None,
        "announced": [str(w.message) for w in caught if str(w.message).startswith(ANNOUNCE)],
        "warnings": [
            str(w.message) for w in caught
            if issubclass(w.category, UserWarning) and not str(w.message).startswith(ANNOUNCE)
        ],
    }))
    """
)


def run_python(code: str, cache: Path, timeout: float = 120, **env: str) -> dict:
    """Run ``code`` in a fresh interpreter on ``cache``; its JSON output (the test fails,
    naming the exit status, where it crashed)."""
    full = {k: v for k, v in os.environ.items() if not k.startswith("SWARM_ENVS_")}
    full.update(PYTHONPATH=str(ROOT), SWARM_ENVS_CACHE=str(cache), **env)
    full[build.PREBUILT_ENV] = "0"  # the cache alone
    for name in ("SWARM_ENVS_NATIVE_ARCH", "CFLAGS"):  # the same flags as this process
        if name in os.environ:
            full[name] = os.environ[name]
    proc = subprocess.run(
        [sys.executable, "-c", code], env=full, capture_output=True, text=True, timeout=timeout
    )
    assert proc.returncode == 0, f"exit status {proc.returncode}: {proc.stderr[-3000:]}"
    return json.loads(proc.stdout.strip().splitlines()[-1])


def script(path: Path, body: str) -> Path:
    path.write_text("#!/bin/sh\n" + textwrap.dedent(body))
    path.chmod(0o755)
    return path


@pytest.fixture(scope="module", autouse=True)
def cache_alone() -> Iterator[None]:
    """The libraries built at install ignored: these tests are about the cache."""
    old = os.environ.get(build.PREBUILT_ENV)
    os.environ[build.PREBUILT_ENV] = "0"
    yield
    if old is None:
        del os.environ[build.PREBUILT_ENV]
    else:
        os.environ[build.PREBUILT_ENV] = old


@pytest.fixture(scope="module")
def golden(tmp_path_factory) -> Path:
    """An intact library for the current flags (built once into the default cache)."""
    ok, why = native_support()
    if not ok:
        pytest.skip(f"C step unavailable: {why}")
    source = build.load_library().path
    folder = tmp_path_factory.mktemp("golden")
    shutil.copy2(source, folder / source.name)
    shutil.copy2(source.with_suffix(".json"), folder / source.with_suffix(".json").name)
    return folder / source.name


@pytest.fixture
def copy_cc(golden, tmp_path) -> Path:
    """A compiler that writes ``golden`` to its ``-o`` and logs each run in ``cc.log``."""
    return script(
        tmp_path / "copy-cc",
        f"""\
        echo run >> {tmp_path / "cc.log"}
        while [ $# -gt 0 ]; do [ "$1" = -o ] && out=$2; shift; done
        cp {golden} "$out"
        """,
    )


@pytest.fixture
def no_compiler(tmp_path) -> dict[str, str]:
    """Child environment without any C or C++ compiler."""
    empty = tmp_path / "empty-path"
    empty.mkdir()
    return {"CC": "/nonexistent/cc", "PATH": str(empty)}


@pytest.fixture
def fresh(monkeypatch, tmp_path) -> Path:
    """The loader's state reset (and restored afterwards), its cache in a new folder."""
    monkeypatch.setattr(build, "_LIBRARIES", {})
    monkeypatch.setattr(build, "_FAILURES", {})
    monkeypatch.setattr(build, "_WARNED", set())
    monkeypatch.setattr(backends, "_WARNED", set())
    monkeypatch.delenv(build.NATIVE_ENV, raising=False)
    monkeypatch.delenv(build.CC_TIMEOUT_ENV, raising=False)
    cache = tmp_path / "cache"
    monkeypatch.setenv(build.CACHE_ENV, str(cache))
    return cache


def damage(library: Path, how: str) -> None:
    if how == "garbage":  # the same size, other bytes
        library.write_bytes(os.urandom(library.stat().st_size))
    elif how == "no record":  # a complete file whose build was never recorded
        library.with_suffix(".json").unlink()
    else:
        os.truncate(library, int(how))


DAMAGE = ["4096", "0", "64", "garbage", "no record"]


# --------------------------------------------------------------------------- damaged


@pytest.mark.parametrize("how", DAMAGE)
def test_a_damaged_library_is_rebuilt_with_a_warning(how, tmp_path, golden, copy_cc):
    cache = tmp_path / "cache"
    first = run_python(PROBE, cache, CC=str(copy_cc))
    assert first["ok"] and first["backend"] == "native" and first["warnings"] == []
    (announced,) = first["announced"]  # a build is announced, once
    assert "building the C step now, as SWARM_ENVS_NATIVE_PREBUILT=0" in announced
    (library,) = cache.glob("fused_step-*.so")
    damage(library, how)
    again = run_python(PROBE, cache, CC=str(copy_cc))
    assert again["ok"] and again["backend"] == "native", again
    assert len(again["warnings"]) == 1 and "was damaged" in again["warnings"][0]
    assert library.read_bytes() == golden.read_bytes()
    assert len((tmp_path / "cc.log").read_text().split()) == 2  # built, then rebuilt
    assert run_python(PROBE, cache, CC=str(copy_cc))["warnings"] == []  # intact again


@pytest.mark.parametrize("how", DAMAGE)
def test_without_a_compiler_a_damaged_library_is_refused_with_a_warning(
    how, tmp_path, golden, no_compiler
):
    cache = tmp_path / "cache"
    cache.mkdir()
    library = cache / golden.name
    shutil.copy2(golden, library)
    shutil.copy2(golden.with_suffix(".json"), library.with_suffix(".json"))
    damage(library, how)
    out = run_python(PROBE, cache, **no_compiler)
    assert not out["ok"] and out["backend"] == "numpy"
    assert "no C compiler found" in out["why"] and "damaged" in out["why"]
    (warning,) = out["warnings"]  # two cores, one warning
    assert "backend 'native' unavailable" in warning and "damaged" in warning
    required = textwrap.dedent(
        """
        import json
        from swarm_envs.envs.cores.native import resolve_native
        try:
            resolve_native(True)
        except RuntimeError as err:
            print(json.dumps({"error": str(err)}))
        """
    )
    error = run_python(required, cache, **no_compiler)["error"]
    assert error.startswith("the C step was required but cannot be used: no C compiler")
    assert "damaged" in error


def test_a_library_truncated_after_its_check_is_not_what_is_loaded(tmp_path, golden):
    # The loader gets a private copy of the bytes checked: damaging the cached file right
    # after the check (the moment a loader reading the file would crash) changes nothing.
    cache = tmp_path / "cache"
    cache.mkdir()
    shutil.copy2(golden, cache / golden.name)
    shutil.copy2(golden.with_suffix(".json"), cache / golden.with_suffix(".json").name)
    code = PROBE.replace(
        "with warnings",
        textwrap.dedent(
            """\
            import os
            checked = build.store.verified
            def check_then_truncate(path, key):
                result = checked(path, key)
                os.truncate(path, 4096)
                return result
            build.store.verified = check_then_truncate
            with warnings"""
        ),
        1,
    )
    out = run_python(code, cache, CC="/nonexistent/cc", PATH=str(tmp_path))
    assert out["ok"] and out["backend"] == "native" and out["warnings"] == []
    assert (cache / golden.name).stat().st_size == 4096


# --------------------------------------------------------------------------- compilers


def test_an_intact_library_loads_without_any_compiler(tmp_path, golden, no_compiler):
    cache = tmp_path / "cache"
    cache.mkdir()
    shutil.copy2(golden, cache / golden.name)
    shutil.copy2(golden.with_suffix(".json"), cache / golden.with_suffix(".json").name)
    out = run_python(PROBE, cache, **no_compiler)
    assert out == {
        "ok": True,
        "why": "supported",
        "backend": "native",
        "path": str(cache / golden.name),
        "announced": [],
        "warnings": [],
    }


def test_a_hung_compiler_is_killed_after_the_timeout(monkeypatch, fresh, tmp_path):
    pid_file = tmp_path / "cc.pid"
    hung = script(tmp_path / "hung-cc", f"echo $$ > {pid_file}\nexec sleep 60\n")
    monkeypatch.setenv("CC", str(hung))
    monkeypatch.setenv(build.CC_TIMEOUT_ENV, "1")
    start = time.monotonic()
    with pytest.warns(UserWarning, match="did not finish within 1 s \\(SWARM_ENVS_CC_TIMEOUT"):
        assert make_core(SwarmConfig(n_agents=4)).backend == "numpy"
    assert time.monotonic() - start < 15
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # once: the second core neither waits nor warns
        assert make_core(SwarmConfig(n_agents=4)).backend == "numpy"
    assert time.monotonic() - start < 15
    pid = int(pid_file.read_text())
    try:
        os.kill(pid, 0)
        alive = True
    except ProcessLookupError:
        alive = False
    assert not alive or Path(f"/proc/{pid}/stat").read_text().split()[2] == "Z"
    assert [p.name for p in fresh.iterdir()] == [p.name for p in fresh.glob(".*.lock")]


def test_a_build_in_another_process_is_waited_for_at_most_the_timeout(monkeypatch, fresh, tmp_path):
    pid_file = tmp_path / "cc.pid"
    hung = script(tmp_path / "hung-cc", f"echo $$ > {pid_file}\nexec sleep 60\n")
    env = {k: v for k, v in os.environ.items() if not k.startswith("SWARM_ENVS_")}
    env.update(
        SWARM_ENVS_NATIVE_PREBUILT="0",
        PYTHONPATH=str(ROOT),
        SWARM_ENVS_CACHE=str(fresh),
        CC=str(hung),
    )
    code = "from swarm_envs.envs.cores.native import native_support; native_support()"
    child = subprocess.Popen([sys.executable, "-c", code], env=env)  # holds the lock
    try:
        for _ in range(300):
            if pid_file.exists() and pid_file.read_text().strip():
                break
            time.sleep(0.1)
        monkeypatch.setenv("CC", str(hung))
        monkeypatch.setenv(build.CC_TIMEOUT_ENV, "1")
        start = time.monotonic()
        ok, why = native_support()
        assert time.monotonic() - start < 10
        assert not ok and "another process has been building" in why
        assert "1 s (SWARM_ENVS_CC_TIMEOUT" in why
    finally:
        child.kill()
        child.wait(timeout=30)
        if pid_file.exists() and pid_file.read_text().strip():
            os.killpg(int(pid_file.read_text()), signal.SIGKILL)


@pytest.mark.parametrize("value", ["abc", "0", "-5", "inf", "nan"])
def test_the_timeout_must_be_a_positive_number_of_seconds(monkeypatch, fresh, value):
    monkeypatch.setenv(build.CC_TIMEOUT_ENV, value)
    with pytest.raises(ValueError, match=f"SWARM_ENVS_CC_TIMEOUT must be .* > 0, got '{value}'"):
        native_support()


def test_concurrent_processes_build_once(tmp_path, golden, copy_cc):
    slow = script(tmp_path / "slow-cc", f'sleep 1\nexec {copy_cc} "$@"\n')
    cache = tmp_path / "cache"
    code = "from swarm_envs.envs.cores.native import native_support; print(native_support()[0])"
    env = {k: v for k, v in os.environ.items() if not k.startswith("SWARM_ENVS_")}
    env.update(
        SWARM_ENVS_NATIVE_PREBUILT="0",
        PYTHONPATH=str(ROOT),
        SWARM_ENVS_CACHE=str(cache),
        CC=str(slow),
    )
    procs = [
        subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.PIPE, text=True)
        for _ in range(3)
    ]
    outs = [p.communicate(timeout=120)[0].strip() for p in procs]
    assert outs == ["True"] * 3 and [p.returncode for p in procs] == [0] * 3
    assert (tmp_path / "cc.log").read_text().split() == ["run"]


# --------------------------------------------------------------------------- leftovers


def test_folders_of_killed_builds_are_removed(monkeypatch, fresh, tmp_path, golden):
    # A build killed with SIGKILL leaves its folder; the next load removes it, and old
    # unnamed ``tmp*`` build folders, but not live builds' folders or foreign folders.
    pid_file = tmp_path / "cc.pid"
    hung = script(tmp_path / "hung-cc", f"echo $$ > {pid_file}\nexec sleep 60\n")
    env = {k: v for k, v in os.environ.items() if not k.startswith("SWARM_ENVS_")}
    env.update(
        SWARM_ENVS_NATIVE_PREBUILT="0",
        PYTHONPATH=str(ROOT),
        SWARM_ENVS_CACHE=str(fresh),
        CC=str(hung),
    )
    code = "from swarm_envs.envs.cores.native import native_support; native_support()"
    child = subprocess.Popen([sys.executable, "-c", code], env=env)
    try:
        for _ in range(300):
            if pid_file.exists() and pid_file.read_text().strip():
                break
            time.sleep(0.1)
        child.send_signal(signal.SIGKILL)
        child.wait(timeout=30)
    finally:
        if pid_file.exists() and pid_file.read_text().strip():
            os.killpg(int(pid_file.read_text()), signal.SIGKILL)  # the orphaned compiler
    (killed,) = fresh.glob(".fused_step-build-*")
    assert killed.name.startswith(f".fused_step-build-{child.pid}-")
    live = fresh / killed.name.replace(f"-{child.pid}-", f"-{os.getpid()}-")
    live.mkdir()
    old = time.time() - 2 * build.LEFTOVER_AGE
    legacy, recent, foreign = fresh / "tmp5x_old", fresh / "tmpq_recent", fresh / "tmp_notes"
    for folder in (legacy, recent):
        folder.mkdir()
        (folder / "step_params.h").write_text("/* generated */")
    (legacy / golden.name).write_bytes(b"\x7fELF")
    foreign.mkdir()
    (foreign / "notes.txt").write_text("not a build")
    for folder in (legacy, foreign):
        os.utime(folder, (old, old))
    shutil.copy2(golden, fresh / golden.name)
    shutil.copy2(golden.with_suffix(".json"), fresh / golden.with_suffix(".json").name)
    monkeypatch.setenv("CC", "/nonexistent/cc")
    monkeypatch.setenv("PATH", str(tmp_path / "nothing"))
    assert native_support() == (True, "supported")
    assert not killed.exists() and not legacy.exists()
    assert live.exists() and recent.exists() and foreign.exists()


# --------------------------------------------------------------------------- warnings


def test_compile_auto_warns_once_per_reason_where_torch_compile_is_unavailable(monkeypatch):
    torch = pytest.importorskip("torch")
    from swarm_envs._runtime import torch_compile as rt

    monkeypatch.setattr(rt, "_WARNED", set())
    monkeypatch.delenv(rt.COMPILE_ENV, raising=False)
    monkeypatch.setattr(rt, "compile_support", lambda device="cpu": "no C++ compiler found")
    with pytest.warns(UserWarning, match=r"torch.compile unavailable \(no C\+\+ compiler"):
        assert not rt.MaybeCompiled(torch.neg).compiled
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert not rt.MaybeCompiled(torch.neg).compiled  # once
        assert not rt.MaybeCompiled(torch.neg, compile=False).compiled  # asked for
        monkeypatch.setenv(rt.COMPILE_ENV, "0")
        monkeypatch.setattr(rt, "_WARNED", set())
        assert not rt.MaybeCompiled(torch.neg).compiled  # switched off on purpose
    monkeypatch.delenv(rt.COMPILE_ENV)
    monkeypatch.setattr(rt, "compile_support", lambda device="cpu": "Triton is not installed")
    with pytest.warns(UserWarning, match="Triton"):  # another reason: warned again
        rt.MaybeCompiled(torch.neg)
