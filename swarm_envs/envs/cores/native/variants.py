"""The C step's prebuilt variants: which are built at install, which one a CPU runs.

The C step is compiled when the package is installed (``setup.py`` calls
:func:`build_variants`): on x86-64 one library per instruction-set level of
:data:`X86_64_VARIANTS` (``portable``: no ``-march``, the compiler's default target, any
x86-64 CPU; ``x86-64-v3``: AVX2 and FMA; ``x86-64-v4``: AVX-512), elsewhere ``portable``
only, built in parallel into ``lib/`` beside the sources as ``fused_step-<variant>.so``,
each with its record ``fused_step-<variant>.json`` (the same record as a cache entry: the
source key over the sources, the generated header and the flags; the parameter layout;
size; SHA-256; compiler; flags). At run time :func:`choose_variant` picks the best level
the CPU supports from its flags in ``/proc/cpuinfo`` (:func:`cpu_flags`).

This module imports nothing but the standard library: the build backend loads it by
its path, without the package's dependencies, and compiles against the committed header
``include/step_params.h`` (the one :func:`swarm_envs.envs.cores.native.contract.header`
generates; a test holds the two equal, and
``python -m swarm_envs.envs.cores.native.write_header`` rewrites it).
"""

from __future__ import annotations

import concurrent.futures
import hashlib
import json
import os
import platform
import re
import shutil
import subprocess
import tempfile
import time
from collections.abc import Iterable, Mapping
from pathlib import Path

__all__ = [
    "BASE_FLAGS",
    "HEADER",
    "HEADER_DIR",
    "LIB_DIR",
    "PORTABLE",
    "RECORD_FORMAT",
    "SOURCES",
    "VARIANT_FLAGS",
    "X86_64_VARIANTS",
    "arch_flags",
    "build_variants",
    "choose_variant",
    "cpu_flags",
    "runnable_variants",
    "shipped_variants",
    "source_key",
    "supports",
]

#: The variant built for the compiler's default target (no ``-march``): a library that
#: runs on any CPU of the architecture.
PORTABLE = "portable"
#: The fixed flags. Where the kernel's vectors are wider than the registers (the
#: ``portable`` build's 64-byte vectors are four SSE2 registers each), GCC's RTL partial
#: redundancy elimination (``-fgcse``) and load CSE
#: after register allocation (``-fgcse-after-reload``) then take most of a build's time
#: over the result; the vectorised loops do not need them (``docs/performance.md``).
BASE_FLAGS = (
    "-O3",
    "-fno-gcse",
    "-fno-gcse-after-reload",
    "-fopenmp",
    "-fno-math-errno",
    "-fno-trapping-math",
    "-fPIC",
    "-shared",
)
#: The files a library is built from (the first is compiled), besides the header.
SOURCES = ("fused_step.c", "fused_step_body.h", "fused_step_stats.h")
#: The generated header (``#include "step_params.h"``): install-time builds compile
#: against its committed copy in :data:`HEADER_DIR`, a folder of its own so that builds
#: at first use, which write the header afresh, never find the copy instead.
HEADER = "step_params.h"
#: The folder of the committed header, beside the sources.
HEADER_DIR = "include"
#: The folder of the prebuilt libraries, beside the sources.
LIB_DIR = "lib"
#: The version of the record's format (shared with the per-user cache's records).
RECORD_FORMAT = 1
#: The x86-64 levels built at install, best last, with the CPU flags (as
#: ``/proc/cpuinfo`` names them) that each needs beyond the previous one.
X86_64_VARIANTS: dict[str, frozenset[str]] = {
    PORTABLE: frozenset(),
    "x86-64-v3": frozenset(
        # x86-64-v2 (pni is SSE3) ...
        {"cx16", "lahf_lm", "popcnt", "pni", "sse4_1", "sse4_2", "ssse3"}
        # ... and v3's own (abm is LZCNT)
        | {"avx", "avx2", "bmi1", "bmi2", "f16c", "fma", "abm", "movbe", "xsave"}
    ),
    "x86-64-v4": frozenset({"avx512f", "avx512bw", "avx512cd", "avx512dq", "avx512vl"}),
}
#: The ``-march`` flags of each variant.
VARIANT_FLAGS: dict[str, tuple[str, ...]] = {
    PORTABLE: (),
    "x86-64-v3": ("-march=x86-64-v3",),
    "x86-64-v4": ("-march=x86-64-v4",),
}
_X86_64 = ("x86_64", "amd64")


def arch_flags(arch: str) -> tuple[str, ...]:
    """The ``-march`` flags of ``arch``: none for :data:`PORTABLE`, else ``-march=<arch>``."""
    return () if arch == PORTABLE else (f"-march={arch}",)


def shipped_variants(machine: str | None = None) -> tuple[str, ...]:
    """The variants built at install on ``machine`` (default: this one), worst first."""
    machine = (machine or platform.machine()).lower()
    return tuple(X86_64_VARIANTS) if machine in _X86_64 else (PORTABLE,)


def cpu_flags(cpuinfo: str | None = None) -> frozenset[str]:
    """The CPU's feature flags: the first ``flags`` line of ``cpuinfo`` (default: read
    from ``/proc/cpuinfo``; empty where it cannot be read)."""
    if cpuinfo is None:
        try:
            with open("/proc/cpuinfo") as fh:
                for line in fh:
                    if line.startswith("flags"):
                        cpuinfo = line
                        break
        except OSError:
            pass
    match = re.search(r"^flags\s*:(.*)$", cpuinfo or "", re.MULTILINE)
    return frozenset(match.group(1).split()) if match else frozenset()


def supports(variant: str, flags: Iterable[str], machine: str | None = None) -> bool:
    """Whether a CPU with these flags runs ``variant`` (each x86-64 level needs its
    own flags and those of the levels below it)."""
    if variant not in shipped_variants(machine):
        return False
    have = set(flags)
    for name, needs in X86_64_VARIANTS.items():
        if not needs <= have:
            return False
        if name == variant:
            return True
    return variant == PORTABLE


def runnable_variants(flags: Iterable[str], machine: str | None = None) -> tuple[str, ...]:
    """The shipped variants that a CPU with these flags runs, worst first."""
    have = frozenset(flags)
    return tuple(v for v in shipped_variants(machine) if supports(v, have, machine))


def choose_variant(
    flags: Iterable[str], available: Iterable[str], machine: str | None = None
) -> str | None:
    """The best of the ``available`` variants that a CPU with these flags runs, or None
    where it runs none of them."""
    present = set(available)
    runnable = [v for v in runnable_variants(flags, machine) if v in present]
    return runnable[-1] if runnable else None


def source_key(src: Path, header_text: str, flags: Iterable[str]) -> str:
    """What a library is built from, without the compiler: the sources in ``src``, the
    generated header, the flags, the machine and, for ``-march=native``, the CPU (hex
    SHA-256)."""
    flags = tuple(flags)
    h = hashlib.sha256()
    for name in SOURCES:
        h.update((src / name).read_bytes())
    h.update(header_text.encode())
    h.update(" ".join(flags).encode())
    h.update(platform.machine().encode())
    if "-march=native" in flags:
        h.update(_cpu_description().encode())
    return h.hexdigest()


def _cpu_description() -> str:
    """The CPU's model and feature flags (``-march=native`` code is built for them)."""
    try:
        with open("/proc/cpuinfo") as fh:
            lines = [ln for ln in fh if ln.startswith(("flags", "model name"))]
        return "".join(sorted(set(lines)))
    except OSError:
        return platform.processor()


def layout_of(header_text: str) -> int:
    """The parameter layout hash the header declares (``STEP_LAYOUT_HASH``)."""
    match = re.search(r"#define STEP_LAYOUT_HASH (\d+)LL", header_text)
    if not match:
        raise ValueError("the header declares no STEP_LAYOUT_HASH")
    return int(match.group(1))


def record(key: str, layout: int, data: bytes, compiler: str, flags: Iterable[str]) -> dict:
    """The record written beside a library: what it was built from and its checksum."""
    return {
        "format": RECORD_FORMAT,
        "key": key,
        "layout": layout,
        "size": len(data),
        "sha256": hashlib.sha256(data).hexdigest(),
        "compiler": os.path.realpath(compiler),
        "flags": list(flags),
    }


def find_compiler() -> str | None:
    """The C compiler: ``$CC``, else ``cc`` or ``gcc`` (a full path), or None."""
    for name in (os.environ.get("CC"), "cc", "gcc"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def _compile_one(
    compiler: str, src: Path, include: Path, flags: tuple[str, ...], out: Path
) -> tuple[float, float]:
    """Compile one library; its (CPU seconds of the compiler and its children, wall
    seconds)."""
    cmd = [compiler, *flags, "-I", str(include), "-I", str(src), "-o", str(out)]
    start = time.perf_counter()
    with tempfile.TemporaryFile() as err:
        proc = subprocess.Popen([*cmd, str(src / SOURCES[0]), "-lm"], stdout=err, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)  # this compiler's own CPU time
        proc.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        message = err.read().decode(errors="replace").strip()
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed: {message[:2000]}")
    return usage.ru_utime + usage.ru_stime, time.perf_counter() - start


def build_variants(
    src: Path,
    out: Path,
    variants: Iterable[str] | None = None,
    compiler: str | None = None,
    jobs: int | None = None,
) -> Mapping[str, tuple[float, float]]:
    """Build ``variants`` (default: :func:`shipped_variants`) of the C step from the
    sources and committed header in ``src`` into ``out``, in parallel (``jobs``
    compilers at once, default one per CPU), each library with its record; returns the
    (CPU seconds, wall seconds) of each build. Libraries already there are replaced.

    Raises:
        RuntimeError: no C compiler, or a build failed (naming the compiler's error).
    """
    compiler = compiler or find_compiler()
    if compiler is None:
        raise RuntimeError("no C compiler found ($CC, cc, gcc)")
    names = tuple(variants) if variants is not None else shipped_variants()
    header_text = (src / HEADER_DIR / HEADER).read_text()
    layout = layout_of(header_text)
    out.mkdir(parents=True, exist_ok=True)
    times: dict[str, tuple[float, float]] = {}
    with tempfile.TemporaryDirectory(prefix=".fused_step-install-", dir=out) as tmp:
        include = Path(tmp) / "include"
        include.mkdir()
        (include / HEADER).write_text(header_text)  # the header the key names, exactly
        flags = {v: (*BASE_FLAGS, *arch_flags(v)) for v in names}
        libs = {v: Path(tmp) / f"fused_step-{v}.so" for v in names}
        workers = max(1, min(len(names), jobs or os.cpu_count() or 1))
        with concurrent.futures.ThreadPoolExecutor(workers) as pool:
            futures = {
                v: pool.submit(_compile_one, compiler, src, include, flags[v], libs[v])
                for v in names
            }
            errors = []
            for v, fut in futures.items():
                try:
                    times[v] = fut.result()
                except RuntimeError as err:
                    errors.append(f"{v}: {err}")
        if errors:
            raise RuntimeError("; ".join(errors))
        for v in names:
            data = libs[v].read_bytes()
            key = source_key(src, header_text, flags[v])
            meta = record(key, layout, data, compiler, flags[v])
            target = out / libs[v].name
            os.replace(libs[v], target)
            target.with_suffix(".json").write_text(json.dumps(meta, indent=1) + "\n")
    return times
