"""The C step built at install (swarm_envs.envs.cores.native.variants and build).

Which variant a CPU runs, from its flags; the committed header equal to the generated
one; the records written at install name the key that the loader computes; a prebuilt
library is preferred over the cache (no build, no warning); a named variant is loaded
as named, and refused where the CPU cannot run it; a stale or damaged prebuilt library,
or a setting no variant fits, falls back to a build into the cache that is announced
with a warning first. Builds here use a fake compiler that copies a library, so they
take milliseconds; the tests that load a prebuilt library need an installed package
(``make install`` builds them; CI requires them).
"""

from __future__ import annotations

import json
import shutil
import textwrap
import time
import warnings
from pathlib import Path

import pytest

from swarm_envs.envs.cores.native import build, contract, variants
from swarm_envs.envs.cores.native.variants import PORTABLE, X86_64_VARIANTS

V3, V4 = "x86-64-v3", "x86-64-v4"
#: The flags of a CPU that runs every x86-64 level (as /proc/cpuinfo names them).
EVERY_LEVEL = frozenset().union(*X86_64_VARIANTS.values()) | {"fpu", "sse", "sse2"}


# --------------------------------------------------------------------------- choice


def test_the_best_level_the_cpu_runs_is_chosen():
    shipped = variants.shipped_variants("x86_64")
    assert shipped == (PORTABLE, V3, V4)
    assert variants.choose_variant(EVERY_LEVEL, shipped, "x86_64") == V4
    for flag in X86_64_VARIANTS[V4]:  # any AVX-512 subset missing: v3
        assert variants.choose_variant(EVERY_LEVEL - {flag}, shipped, "x86_64") == V3
    for flag in X86_64_VARIANTS[V3]:  # v3 needs all of v2's and its own: else portable
        assert variants.choose_variant(EVERY_LEVEL - {flag}, shipped, "x86_64") == PORTABLE
    assert variants.choose_variant(set(), shipped, "x86_64") == PORTABLE


def test_only_the_variants_present_are_chosen():
    assert variants.choose_variant(EVERY_LEVEL, [PORTABLE, V3], "x86_64") == V3
    assert variants.choose_variant(EVERY_LEVEL, [PORTABLE], "x86_64") == PORTABLE
    assert variants.choose_variant(EVERY_LEVEL, [V4], "x86_64") == V4
    assert variants.choose_variant({"avx2"}, [V3, V4], "x86_64") is None
    assert variants.choose_variant(EVERY_LEVEL, [], "x86_64") is None


def test_other_architectures_ship_the_portable_build_only():
    assert variants.shipped_variants("aarch64") == (PORTABLE,)
    assert variants.choose_variant(EVERY_LEVEL, [PORTABLE, V3, V4], "aarch64") == PORTABLE
    assert not variants.supports(V3, EVERY_LEVEL, "aarch64")


def test_cpu_flags_are_read_from_the_first_flags_line():
    cpuinfo = "processor\t: 0\nflags\t\t: fpu avx2 fma\nbugs\t\t: spectre\nflags\t: sse\n"
    assert variants.cpu_flags(cpuinfo) == {"fpu", "avx2", "fma"}
    assert variants.cpu_flags("processor: 0\n") == frozenset()


def test_variant_flags_are_the_arch_flags():
    for name, flags in variants.VARIANT_FLAGS.items():
        assert variants.arch_flags(name) == flags
    assert variants.arch_flags("native") == ("-march=native",)


# --------------------------------------------------------------------------- header


def test_the_committed_header_is_the_generated_one():
    # Builds at install compile against this copy; regenerate it with
    # `python -m swarm_envs.envs.cores.native.write_header`.
    path = contract.header_path()
    assert path.read_text() == contract.header(), f"{path} is stale: rewrite it"
    assert variants.layout_of(path.read_text()) == contract.layout_hash()


def test_write_header_writes_the_generated_header(tmp_path):
    out = contract.write_header(tmp_path / "include" / "step_params.h")
    assert out.read_text() == contract.header()


# --------------------------------------------------------------------------- install


def fake_compiler(tmp_path: Path, library: Path) -> Path:
    """A compiler that writes ``library`` to its ``-o`` and logs each run in cc.log."""
    cc = tmp_path / "copy-cc"
    cc.write_text(
        textwrap.dedent(
            f"""\
            #!/bin/sh
            echo "$@" >> {tmp_path / "cc.log"}
            while [ $# -gt 0 ]; do [ "$1" = -o ] && out=$2; shift; done
            cp {library} "$out"
            """
        )
    )
    cc.chmod(0o755)
    return cc


def test_install_records_name_the_key_the_loader_computes(tmp_path):
    # The record of each variant built at install (from the committed header, without
    # the package) vouches for the library under the loader's own key.
    lib = tmp_path / "any.so"
    lib.write_bytes(b"\x7fELF stand-in")
    cc = fake_compiler(tmp_path, lib)
    out = tmp_path / "lib"
    times = variants.build_variants(build._source_dir(), out, [PORTABLE, V3], str(cc))
    assert set(times) == {PORTABLE, V3} and all(cpu >= 0 for cpu, _ in times.values())
    for name in (PORTABLE, V3):
        key = build._source_key((*variants.BASE_FLAGS, *variants.arch_flags(name)))
        data, why = build.store.verified(out / f"fused_step-{name}.so", key)
        assert data == lib.read_bytes(), why
        assert json.loads((out / f"fused_step-{name}.json").read_text())["compiler"] == str(cc)
    assert len((tmp_path / "cc.log").read_text().splitlines()) == 2
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []  # no leftovers


def test_a_failing_install_build_names_the_variant_and_the_error(tmp_path):
    cc = tmp_path / "cc"
    cc.write_text("#!/bin/sh\necho 'cc: fatal error: out of cheese' >&2\nexit 1\n")
    cc.chmod(0o755)
    with pytest.raises(RuntimeError, match=r"portable: .*out of cheese"):
        variants.build_variants(build._source_dir(), tmp_path / "lib", [PORTABLE], str(cc))
    assert not list((tmp_path / "lib").glob("fused_step-*"))


# --------------------------------------------------------------------------- loading


@pytest.fixture
def fresh(monkeypatch, tmp_path) -> Path:
    """The loader's state reset (and restored afterwards), its cache in a new folder."""
    monkeypatch.setattr(build, "_LIBRARIES", {})
    monkeypatch.setattr(build, "_FAILURES", {})
    monkeypatch.setattr(build, "_WARNED", set())
    for name in (build.NATIVE_ENV, build.ARCH_ENV, build.PREBUILT_ENV, "CFLAGS"):
        monkeypatch.delenv(name, raising=False)
    cache = tmp_path / "cache"
    monkeypatch.setenv(build.CACHE_ENV, str(cache))
    return cache


@pytest.fixture
def installed() -> dict[str, Path]:
    """The prebuilt libraries this CPU runs (skips where the package was not built)."""
    runnable = variants.runnable_variants(variants.cpu_flags())
    found = {v: build._prebuilt_path(v) for v in runnable if build._prebuilt_path(v).exists()}
    if not found:
        pytest.skip(f"no C step built at install in {build.prebuilt_dir()} (make install)")
    return found


@pytest.fixture
def copied(monkeypatch, tmp_path, installed) -> Path:
    """A copy of the prebuilt folder, which the loader then reads."""
    lib = tmp_path / "prebuilt"
    lib.mkdir()
    for path in installed.values():
        shutil.copy2(path, lib / path.name)
        shutil.copy2(path.with_suffix(".json"), lib / path.with_suffix(".json").name)
    monkeypatch.setattr(build, "prebuilt_dir", lambda: lib)
    return lib


def test_the_best_prebuilt_variant_is_loaded_without_a_build(monkeypatch, fresh, installed):
    monkeypatch.setattr(build, "_compiler", lambda: pytest.fail("no build expected"))
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        library = build.load_library()
    assert time.perf_counter() - start < 1.0  # the choice and the check are quick
    best = variants.choose_variant(variants.cpu_flags(), installed)
    assert library.variant == best and library.path == installed[best]
    assert not fresh.exists() or not list(fresh.glob("fused_step-*"))


def test_a_named_variant_is_loaded_as_named(monkeypatch, fresh, installed):
    monkeypatch.setattr(build, "_compiler", lambda: pytest.fail("no build expected"))
    for name in installed:
        monkeypatch.setenv(build.ARCH_ENV, name)
        library = build.load_library()
        assert library.variant == name and library.path == installed[name]
    assert {v: ok for v, (ok, _) in build.prebuilt_support().items()} == dict.fromkeys(
        installed, True
    )


def test_a_variant_this_cpu_cannot_run_is_refused(monkeypatch, fresh):
    monkeypatch.setattr(variants, "cpu_flags", lambda cpuinfo=None: frozenset({"sse2"}))
    monkeypatch.setenv(build.ARCH_ENV, V4)
    ok, why = build.native_support()
    if variants.shipped_variants() != (PORTABLE, V3, V4):
        pytest.skip("not x86-64")
    assert not ok and f"this CPU cannot run the {V4} C step" in why


@pytest.mark.parametrize("how", ["stale", "damaged"])
def test_an_unfit_prebuilt_library_falls_back_to_an_announced_build(
    monkeypatch, fresh, copied, installed, tmp_path, how
):
    best = variants.choose_variant(variants.cpu_flags(), installed)
    library = copied / f"fused_step-{best}.so"
    if how == "stale":  # built from other sources (an edited source tree)
        record = json.loads(library.with_suffix(".json").read_text())
        library.with_suffix(".json").write_text(json.dumps({**record, "key": "0" * 64}))
    else:
        library.write_bytes(library.read_bytes()[:4096])
    monkeypatch.setenv("CC", str(fake_compiler(tmp_path, installed[best])))
    with pytest.warns(UserWarning, match="building the C step now") as caught:
        loaded = build.load_library()
    (message,) = [str(w.message) for w in caught]
    assert f"the prebuilt {best} library" in message and "-march=native" in message
    assert ("other sources" if how == "stale" else "bytes where") in message
    assert loaded.variant is None and loaded.path.parent == fresh
    assert len((tmp_path / "cc.log").read_text().splitlines()) == 1
    build._LIBRARIES.clear()  # a new process: the cached build, silently
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert build.load_library().path == loaded.path


@pytest.mark.parametrize(
    ("setting", "reason"),
    [
        ({build.ARCH_ENV: "native"}, "SWARM_ENVS_NATIVE_ARCH=native is not a variant built"),
        ({"CFLAGS": "-DEXTRA=1"}, "$CFLAGS is set"),
        ({build.PREBUILT_ENV: "0"}, "SWARM_ENVS_NATIVE_PREBUILT=0"),
    ],
)
def test_settings_no_variant_fits_build_into_the_cache_after_saying_why(
    monkeypatch, fresh, installed, tmp_path, setting, reason
):
    best = variants.choose_variant(variants.cpu_flags(), installed)
    monkeypatch.setenv("CC", str(fake_compiler(tmp_path, installed[best])))
    for name, value in setting.items():
        monkeypatch.setenv(name, value)
    with pytest.warns(UserWarning, match="building the C step now") as caught:
        loaded = build.load_library()
    assert reason in str(caught[0].message) and "usually takes" in str(caught[0].message)
    assert loaded.variant is None and loaded.path.parent == fresh


def test_without_any_prebuilt_library_or_compiler_the_reason_names_both(
    monkeypatch, fresh, tmp_path
):
    # A source tree that was not installed, on a machine without a compiler.
    monkeypatch.setattr(build, "prebuilt_dir", lambda: tmp_path / "nothing")
    monkeypatch.setattr(build, "_compiler", lambda: None)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # without a compiler nothing is built: no warning
        ok, why = build.native_support()
    assert not ok and "no C compiler found" in why and "no C step was built at install" in why
