"""Every ```python block of README.md runs alone, in a fresh interpreter, in an empty
folder: each block carries its own imports. Blocks that train (``.learn(``) run with
``--runslow`` only."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BLOCKS = re.findall(
    r"^```python\n(.*?)^```", (ROOT / "README.md").read_text(encoding="utf-8"), re.S | re.M
)


def _trains(code: str) -> bool:
    return ".learn(" in code


def test_readme_has_python_blocks():
    assert len(BLOCKS) >= 4 and any(_trains(b) for b in BLOCKS)


@pytest.mark.parametrize(
    "code",
    [pytest.param(b, marks=[pytest.mark.slow] if _trains(b) else []) for b in BLOCKS],
    ids=[f"block{i}" for i in range(len(BLOCKS))],
)
def test_readme_block_runs_alone(code: str, tmp_path: Path):
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}
    proc = subprocess.run(
        [sys.executable, "-c", code],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=1800,
    )
    assert proc.returncode == 0, f"README block fails alone:\n{code}\n{proc.stderr[-3000:]}"
