"""Build step of the package: the C step is compiled at install (pyproject.toml holds the
metadata).

``pip install .`` (a wheel) and ``pip install -e .`` (``make install``) compile the C step
of ``swarm_envs/envs/cores/native`` into its ``lib/`` folder, in the variants that
``swarm_envs.envs.cores.native.variants`` names for this machine, built in parallel. The
build backend runs without the package's dependencies, so that module (standard library
only) is loaded by its path, and the sources are compiled against the committed copy of
the generated header.

Without a C compiler, or where a build fails, the package is installed without them and
warns (the C step is then built at first use, or the numpy core runs); with
``SWARM_ENVS_NATIVE=1`` (CI) the install fails instead. ``SWARM_ENVS_NATIVE=0`` builds
nothing. The C step is built on Linux only.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path
from types import ModuleType

from setuptools import Distribution, setup
from setuptools.command.build_ext import build_ext

ROOT = Path(__file__).resolve().parent
NATIVE = Path("swarm_envs", "envs", "cores", "native")


def _variants() -> ModuleType:
    """swarm_envs.envs.cores.native.variants, loaded by its path (without the package)."""
    path = ROOT / NATIVE / "variants.py"
    spec = importlib.util.spec_from_file_location("_swarm_envs_variants", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class BuildWithCStep(build_ext):
    """``build_ext``, then the C step's variants: into the build folder for a wheel, into
    the source tree for an editable install (or ``python setup.py build_ext --inplace``).
    Not ``build_py``: an editable install ignores a customised ``build_py`` that fails."""

    def run(self) -> None:
        super().run()
        switch = os.environ.get("SWARM_ENVS_NATIVE", "auto").strip().lower()
        if switch == "0" or not sys.platform.startswith("linux"):
            return
        variants = _variants()
        base = ROOT if self.editable_mode or self.inplace else Path(self.build_lib)
        out = base / NATIVE / variants.LIB_DIR
        names = ", ".join(variants.shipped_variants())
        print(f"building the C step ({names}) in parallel into {out}", file=sys.stderr)
        try:
            times = variants.build_variants(ROOT / NATIVE, out)
        except (OSError, RuntimeError) as err:
            if switch == "1":
                raise RuntimeError(f"the C step could not be built: {err}") from err
            self.warn(f"the C step was not built ({err}); it is built at first use instead")
            return
        for name, (cpu, wall) in times.items():
            print(f"built the C step {name}: {cpu:.1f} s CPU, {wall:.1f} s wall", file=sys.stderr)


class BinaryDistribution(Distribution):
    """A wheel that holds compiled libraries is tagged for its platform (and ``build``
    runs ``build_ext``)."""

    def has_ext_modules(self) -> bool:
        return True


setup(cmdclass={"build_ext": BuildWithCStep}, distclass=BinaryDistribution)
