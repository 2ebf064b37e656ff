"""The benchmark's bootstrap on synthetic data: coverage, determinism, degenerate cases."""

from __future__ import annotations

import json

import numpy as np
import pytest

from train.benchmark.stats import (
    STATISTICS,
    bootstrap,
    interquartile_mean,
    mean_over_defined,
    summarize_runs,
)

MEAN = {"mean": lambda d: d["x"].mean(axis=(-2, -1))}


def covered(rng, trials: int, seeds: int, episodes: int, seed_sd: float, pooled: bool) -> float:
    """Fraction of trials whose 95 % interval holds the true mean 0."""
    hits = 0
    widths = []
    for t in range(trials):
        x = rng.normal(0.0, seed_sd, (seeds, 1)) + rng.normal(0.0, 1.0, (seeds, episodes))
        if pooled:
            x = x.reshape(1, -1)
        iv = bootstrap({"x": x}, MEAN, n_resamples=600, seed=t)["mean"]
        hits += iv.low <= 0.0 <= iv.high
        widths.append(iv.high - iv.low)
    return hits / trials, float(np.mean(widths))


def test_episode_bootstrap_covers_the_mean_about_95_percent():
    coverage, _ = covered(np.random.default_rng(1), 300, 1, 60, 0.0, pooled=False)
    assert 0.89 <= coverage <= 0.99


def test_hierarchical_bootstrap_accounts_for_the_seed_variance():
    rng = np.random.default_rng(2)
    coverage, width = covered(rng, 200, 10, 20, 1.0, pooled=False)
    naive, naive_width = covered(rng, 200, 10, 20, 1.0, pooled=True)
    # Seeds differ (sd 1 between seeds): resampling seeds covers; pooling the episodes
    # as if they were independent gives far too narrow an interval.
    assert coverage >= 0.85
    assert naive < 0.6 and width > 2 * naive_width


def test_same_seed_same_intervals_other_seed_other_intervals():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(3, 40))
    a = bootstrap({"x": x}, MEAN, n_resamples=500, seed=7)
    b = bootstrap({"x": x}, MEAN, n_resamples=500, seed=7)
    c = bootstrap({"x": x}, MEAN, n_resamples=500, seed=8)
    assert a == b
    assert (a["mean"].low, a["mean"].high) != (c["mean"].low, c["mean"].high)
    assert a["mean"].value == c["mean"].value == pytest.approx(x.mean())


def test_resampling_in_chunks_is_reproducible_and_agrees(monkeypatch):
    import train.benchmark.stats as stats

    x = np.random.default_rng(4).normal(size=(2, 30))
    whole = bootstrap({"x": x}, MEAN, n_resamples=2000, seed=1)["mean"]
    monkeypatch.setattr(stats, "CHUNK_VALUES", 60 * 7)  # chunks of 7 resamples
    chunked = bootstrap({"x": x}, MEAN, n_resamples=2000, seed=1)["mean"]
    assert bootstrap({"x": x}, MEAN, n_resamples=2000, seed=1)["mean"] == chunked
    # Other draws of the same distribution: the same interval up to Monte Carlo error.
    assert chunked.value == whole.value
    assert chunked.low == pytest.approx(whole.low, abs=0.05)
    assert chunked.high == pytest.approx(whole.high, abs=0.05)


def test_one_seed_is_the_episode_bootstrap_and_intervals_hold_the_value():
    rng = np.random.default_rng(5)
    r = summarize_runs(
        rng.normal(size=(1, 25)), rng.random((1, 25)) < 0.5, np.full((1, 25), 10), 0.1
    )
    assert r["n_seeds"] == 1 and r["n_episodes"] == 25
    for name in STATISTICS:
        lo, hi = r[name]["ci"]
        assert lo <= r[name]["value"] <= hi
        assert r["per_seed"][name] == [pytest.approx(r[name]["value"])]


def test_all_equal_values_give_a_zero_width_interval():
    r = summarize_runs(np.full((3, 10), 2.5), np.ones((3, 10), bool), np.full((3, 10), 40), 0.1)
    assert r["return"] == {"value": 2.5, "ci": [2.5, 2.5], "defined_resamples": 1.0}
    assert r["success"]["ci"] == [1.0, 1.0]
    assert r["time_to_goal"]["value"] == pytest.approx(4.0)
    assert r["time_to_goal"]["ci"] == [pytest.approx(4.0)] * 2
    assert r["iqm_return"]["ci"] == [2.5, 2.5]


def test_no_success_leaves_the_time_to_goal_undefined_and_json_clean():
    returns = np.random.default_rng(6).normal(size=(2, 8))
    r = summarize_runs(returns, np.zeros((2, 8), bool), np.full((2, 8), 400), 0.1)
    assert r["success"]["value"] == 0.0 and r["success"]["ci"] == [0.0, 0.0]
    assert r["time_to_goal"] == {"value": None, "ci": None, "defined_resamples": 0.0}
    assert r["per_seed"]["time_to_goal"] == [None, None]
    json.dumps(r, allow_nan=False)


def test_rare_success_reports_where_the_time_to_goal_is_defined():
    success = np.zeros((1, 50), bool)
    success[0, 0] = True
    r = summarize_runs(np.zeros((1, 50)), success, np.full((1, 50), 30), 0.1)
    # P(episode 0 is drawn at least once in 50 draws) = 1 - (49/50)^50 ≈ 0.636.
    assert 0.55 < r["time_to_goal"]["defined_resamples"] < 0.72
    assert r["time_to_goal"]["ci"] == [pytest.approx(3.0)] * 2


def test_per_seed_values_are_each_seeds_own_measures():
    rng = np.random.default_rng(7)
    returns = rng.normal(size=(3, 12))
    success = rng.random((3, 12)) < 0.6
    steps = rng.integers(5, 50, (3, 12))
    r = summarize_runs(returns, success, steps, 0.2, n_resamples=50)
    assert r["per_seed"]["return"] == pytest.approx(returns.mean(axis=1).tolist())
    assert r["per_seed"]["success"] == pytest.approx(success.mean(axis=1).tolist())
    for k in range(3):
        times = steps[k][success[k]] * 0.2
        expected = times.mean() if times.size else None
        assert r["per_seed"]["time_to_goal"][k] == pytest.approx(expected)
    pooled = (steps * 0.2)[success].mean()
    assert r["time_to_goal"]["value"] == pytest.approx(pooled)


def test_interquartile_mean_trims_a_quarter_at_each_end():
    x = np.array([[10.0, -50.0, 1.0, 2.0], [3.0, 4.0, 5.0, 99.0]])  # 8 values: cut 2 each end
    assert float(interquartile_mean(x)) == pytest.approx(np.mean([2.0, 3.0, 4.0, 5.0]))
    assert float(interquartile_mean(np.array([[7.0]]))) == 7.0
    batch = np.stack([x, x + 1.0])
    assert interquartile_mean(batch) == pytest.approx([3.5, 4.5])


def test_mean_over_defined_skips_nan_without_warnings():
    x = np.array([[[np.nan, 2.0], [4.0, np.nan]], [[np.nan, np.nan], [np.nan, np.nan]]])
    out = mean_over_defined(x)
    assert out[0] == 3.0 and np.isnan(out[1])


@pytest.mark.parametrize(
    ("data", "kwargs", "match"),
    [
        ({"x": np.zeros((2, 3)), "y": np.zeros((2, 4))}, {}, "one shape"),
        ({"x": np.zeros((0, 3))}, {}, "each >= 1"),
        ({"x": np.zeros(3)}, {}, "one shape"),
        ({"x": np.zeros((2, 3))}, {"n_resamples": 0}, "n_resamples"),
        ({"x": np.zeros((2, 3))}, {"confidence": 1.0}, "confidence"),
    ],
)
def test_bad_input_is_refused(data, kwargs, match):
    with pytest.raises(ValueError, match=match):
        bootstrap(data, MEAN, **kwargs)
