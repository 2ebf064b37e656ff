"""The evaluation figures leave out panels that carry nothing and keep the spread of a
measure that cannot be negative at or above 0."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure

from train.evaluate.figures import informative, plot_robustness, plot_transfer


def _measures(success: float, collisions: float) -> dict:
    return {
        "success_rate": success,
        "success_ci95": [max(success - 0.2, 0.0), min(success + 0.2, 1.0)],
        "mean_return": 5.0 * success - 1.0,
        "std_return": 2.0,
        "mean_time_to_goal": 3.0 if success else None,
        "std_time_to_goal": 5.0 if success else None,  # larger than the mean
        "collisions_per_episode": collisions,
        "std_collisions": collisions,
        "final_fraction_arrived": success,
    }


def _figures(plot, results, path: Path) -> list[Figure]:
    figures = []
    save = Figure.savefig

    def spy(fig, *args, **kwargs):
        figures.append(fig)
        return save(fig, *args, **kwargs)

    with pytest.MonkeyPatch.context() as m:
        m.setattr(Figure, "savefig", spy)
        plot(results, path)
    return figures


def _panels(fig: Figure) -> list[str]:
    return [ax.get_title() for ax in fig.axes if ax.get_visible()]


def _lowest_band(fig: Figure, title_start: str) -> float:
    ax = next(a for a in fig.axes if a.get_title().startswith(title_start))
    bands = [c for c in ax.collections if isinstance(c, PolyCollection)]
    return min(float(np.min(p.vertices[:, 1])) for c in bands for p in c.get_paths())


def test_robustness_leaves_out_collisions_that_never_happen(tmp_path: Path):
    rows = [
        {"option": "failed_fraction", "value": v, "policies": {"a": _measures(s, 0.0)}}
        for v, s in ((0.0, 1.0), (0.5, 0.4))
    ]
    results = {"sweeps": {"failed_fraction": [0.0, 0.5]}, "rows": rows, "episodes": 4}
    results |= {"seed": 0, "on_unstable": "truncate"}
    assert not informative(rows, "collisions_per_episode", "std_collisions")
    assert informative(rows, "success_rate", "success_ci95")
    (fig,) = _figures(plot_robustness, results, tmp_path / "r.png")
    titles = _panels(fig)
    assert len(titles) == 4 and not any(t.startswith("collisions") for t in titles)
    assert "left out, 0 everywhere: collisions per episode" in fig.get_suptitle()
    assert _lowest_band(fig, "time to goal") >= 0.0  # 3 ± 5 stops at 0
    assert _lowest_band(fig, "return") < 0.0  # a return may be negative

    for row in rows:  # collisions happen: the panel is back
        row["policies"]["a"]["collisions_per_episode"] = 0.5
    (fig,) = _figures(plot_robustness, results, tmp_path / "r2.png")
    assert len(_panels(fig)) == 5 and "left out" not in fig.get_suptitle()


def test_transfer_leaves_out_empty_panels_and_clips_bands(tmp_path: Path):
    sizes = [
        {"n_agents": n, "policies": {"a": _measures(1.0, 0.0), "b": _measures(0.5, 0.0)}}
        for n in (10, 100)
    ]
    results = {"sizes": sizes, "episodes": 4, "on_unstable": "truncate"}
    (fig,) = _figures(plot_transfer, results, tmp_path / "t.png")
    titles = _panels(fig)
    assert len(titles) == 3 and not any(t.startswith("collisions") for t in titles)
    assert _lowest_band(fig, "time to goal") >= 0.0
