"""Tests of swarm_envs.render: frames, viewport, renderer state, GIF output, lazy imports.

``rgb_array`` frames are uint8 H×W×3, not blank, change after steps; ``close()`` twice
is safe (docs/testing.md). Plus the drawing details an environment relies on.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from swarm_envs.render import (
    AGENT_COLOR,
    BACKGROUND_COLOR,
    GOAL_COLOR,
    SwarmRenderer,
    Viewport,
    annotate,
    draw_swarm,
    scale_bar_length,
    write_gif,
)

RNG = np.random.default_rng(0)
X = RNG.normal(size=(12, 2))
VP = Viewport(center=(0.0, 0.0), half_width=4.0, size=(200, 200))


def n_colors(frame: np.ndarray) -> int:
    return len(np.unique(frame.reshape(-1, 3), axis=0))


def pixel(frame: np.ndarray, vp: Viewport, point) -> np.ndarray:
    col, row = np.rint(vp.to_pixels(np.asarray(point, dtype=float))).astype(int)
    return frame[row, col].astype(int)


def close_to(rgb: np.ndarray, ref, tol: int = 6) -> bool:
    return bool(np.all(np.abs(rgb - np.asarray(ref)) <= tol))


# --------------------------------------------------------------------------- frames


@pytest.mark.parametrize("size", [(400, 400), (300, 200), (64, 96)])
def test_frame_dtype_and_shape(size):
    frame = draw_swarm(X, goal=np.ones(2), goal_radius=1.0, size=size)
    assert frame.dtype == np.uint8
    assert frame.shape == (size[1], size[0], 3)
    assert frame.flags.c_contiguous


def test_frame_not_blank_and_mostly_background():
    frame = draw_swarm(X, goal=np.array([2.0, 1.0]), goal_radius=1.0, trails=X[None] - 0.1)
    assert n_colors(frame) >= 8
    background = np.all(frame == BACKGROUND_COLOR, axis=-1).mean()
    assert 0.3 < background < 0.99


def test_agent_and_goal_pixels_have_their_colours():
    x = np.array([[-2.0, -2.0], [2.0, -2.0]])
    goal = np.array([0.0, 2.0])
    frame = draw_swarm(x, goal=goal, goal_radius=1.0, viewport=VP)
    assert close_to(pixel(frame, VP, x[0]), AGENT_COLOR)
    assert close_to(pixel(frame, VP, x[1]), AGENT_COLOR)
    assert close_to(pixel(frame, VP, goal), GOAL_COLOR)
    # The goal-radius ring passes through goal + (r, 0) and goal - (0, r).
    for p in (goal + np.array([1.0, 0.0]), goal - np.array([0.0, 1.0])):
        assert close_to(pixel(frame, VP, p), GOAL_COLOR, tol=40)
    # Inside the ring, away from the cross: a faint tint, not plain background.
    inside = pixel(frame, VP, goal + np.array([0.5, 0.3]))
    assert not close_to(inside, BACKGROUND_COLOR, tol=0)
    assert close_to(inside, BACKGROUND_COLOR, tol=40)


def test_y_axis_points_up():
    vp = Viewport(center=(0.0, 0.0), half_width=1.0, size=(100, 100))
    (c0, r0), (c1, r1) = vp.to_pixels(np.array([[0.0, 0.0], [0.5, 0.5]]))
    assert c1 > c0 and r1 < r0


def test_moving_agents_changes_frame():
    f0 = draw_swarm(X, viewport=VP)
    f1 = draw_swarm(X + np.array([0.3, 0.0]), viewport=VP)
    assert not np.array_equal(f0, f1)
    assert np.array_equal(f0, draw_swarm(X, viewport=VP))  # deterministic


def test_trails_change_frame_and_fade_with_age():
    x = np.array([[2.0, 0.0]])
    trail = np.stack([np.array([[t, 0.0]]) for t in np.linspace(-3.0, 1.5, 10)])
    plain = draw_swarm(x, viewport=VP)
    with_trail = draw_swarm(x, trails=trail, viewport=VP)
    assert not np.array_equal(plain, with_trail)
    old = pixel(with_trail, VP, [-2.75, 0.0]).sum()
    new = pixel(with_trail, VP, [1.25, 0.0]).sum()
    background = sum(BACKGROUND_COLOR)
    assert new < old < background  # older segments are fainter (closer to white)


def test_velocities_change_frame():
    f0 = draw_swarm(X, viewport=VP)
    f1 = draw_swarm(X, velocities=np.tile([1.0, 0.0], (len(X), 1)), viewport=VP)
    assert not np.array_equal(f0, f1)
    # Zero velocity draws no tick.
    assert np.array_equal(f0, draw_swarm(X, velocities=np.zeros_like(X), viewport=VP))


def test_per_agent_colours():
    x = np.array([[-2.0, 0.0], [2.0, 0.0]])
    colors = np.array([[200, 30, 30], [30, 160, 30]], dtype=np.uint8)
    frame = draw_swarm(x, colors=colors, trails=x[None] - 0.5, viewport=VP)
    assert close_to(pixel(frame, VP, x[0]), colors[0])
    assert close_to(pixel(frame, VP, x[1]), colors[1])


@pytest.mark.parametrize(
    "x",
    [
        np.zeros((1, 2)),  # N = 1
        np.full((20, 2), 0.7),  # all agents coincident
        np.full((5, 3), -2.5),  # 3-D, coincident
        np.array([[1e6, -1e6], [1e6 + 1.0, -1e6]]),  # far away
        np.array([[0.0, 0.0], [1e6, 1e6]]),  # huge spread
    ],
)
def test_degenerate_swarms_render(x):
    goal = x[0] + 1.0
    frame = draw_swarm(x, goal=goal, goal_radius=0.5, trails=x[None], velocities=np.ones_like(x))
    assert frame.shape == (400, 400, 3) and frame.dtype == np.uint8
    assert n_colors(frame) >= 4
    vp = Viewport.fit(np.concatenate([x[:, :2], x[:, :2]]), goal, goal_radius=0.5)
    assert np.all(np.isfinite(vp.to_pixels(x)))
    plain = draw_swarm(x, goal=goal, goal_radius=0.5)  # no heading tick over the centre
    assert close_to(pixel(plain, vp, x[-1]), AGENT_COLOR)


def test_agents_outside_a_fixed_viewport_are_clipped():
    x = np.array([[1e6, 0.0], [-1e9, 1e9], [0.0, 0.0]])
    trails = np.stack([x * 0.5, x * 0.9])
    frame = draw_swarm(x, trails=trails, goal=np.array([1e7, 0.0]), goal_radius=1e7, viewport=VP)
    assert frame.shape == (200, 200, 3)
    assert close_to(pixel(frame, VP, [0.0, 0.0]), AGENT_COLOR)


def test_empty_swarm():
    frame = draw_swarm(np.zeros((0, 2)), goal=np.zeros(2), goal_radius=1.0)
    assert frame.shape == (400, 400, 3)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"x": np.array([[np.nan, 0.0]])},
        {"x": np.array([[np.inf, 0.0]])},
        {"x": np.zeros((3, 4))},
        {"x": np.zeros(3)},
        {"x": np.zeros((3, 2)), "goal": np.array([np.nan, 0.0])},
        {"x": np.zeros((3, 2)), "goal": np.zeros(2), "goal_radius": -1.0},
        {"x": np.zeros((3, 2)), "trails": np.zeros((4, 2, 2))},
        {"x": np.zeros((3, 2)), "velocities": np.zeros((2, 2))},
        {"x": np.zeros((3, 2)), "colors": np.zeros((2, 3))},
        {"x": np.zeros((3, 2)), "colors": np.full((3, 3), 300)},
        {"x": np.zeros((3, 2)), "size": (0, 10)},
        {"x": np.zeros((3, 2)), "agent_radius_px": 0.0},
    ],
)
def test_bad_input_raises_value_error(kwargs):
    x = kwargs.pop("x")
    with pytest.raises(ValueError):
        draw_swarm(x, **kwargs)


# --------------------------------------------------------------------------- viewport


def test_viewport_fit_contains_points_and_goal():
    pts = np.array([[-3.0, 1.0], [5.0, 2.0], [0.0, -1.0]])
    goal = np.array([1.0, 8.0])
    vp = Viewport.fit(pts, goal, margin=0.1, size=(300, 200))
    px = vp.to_pixels(np.concatenate([pts, goal[None]]))
    assert np.all(px[:, 0] >= 0) and np.all(px[:, 0] <= 299)
    assert np.all(px[:, 1] >= 0) and np.all(px[:, 1] <= 199)
    assert vp.size == (300, 200)


def test_viewport_fit_single_point_uses_min_half_width():
    vp = Viewport.fit(np.array([[3.0, -4.0]]), min_half_width=2.5)
    assert vp.center == (3.0, -4.0)
    assert vp.half_width == 2.5


def test_viewport_rejects_bad_values():
    with pytest.raises(ValueError):
        Viewport(half_width=0.0)
    with pytest.raises(ValueError):
        Viewport(center=(np.nan, 0.0))
    with pytest.raises(ValueError):
        Viewport.fit(np.zeros((2, 2)), margin=-1.0)
    with pytest.raises(ValueError):
        Viewport.fit(np.array([[np.nan, 0.0]]))


# --------------------------------------------------------------------------- renderer


def test_renderer_frames_change_after_steps_and_close_twice():
    r = SwarmRenderer(size=(160, 120), trail_length=10)
    x = X.copy()
    frames = []
    for _ in range(5):
        x = x + 0.2
        r.record(x)
        frames.append(r.frame(x, goal=np.zeros(2), goal_radius=1.0, velocities=np.ones_like(x)))
    assert all(f.shape == (120, 160, 3) and f.dtype == np.uint8 for f in frames)
    assert not np.array_equal(frames[0], frames[-1])
    r.close()
    r.close()


def test_renderer_trail_and_reset():
    vp = Viewport(center=(0.0, 0.0), half_width=3.0, size=(120, 120))
    r = SwarmRenderer(trail_length=5, viewport=vp)
    x = np.array([[2.0, 0.0]])
    bare = r.frame(x)
    for t in np.linspace(-2.0, 2.0, 8):
        r.record(np.array([[t, 0.0]]))
    assert not np.array_equal(r.frame(x), bare)
    r.reset()
    assert np.array_equal(r.frame(x), bare)
    assert r.viewport == vp


def test_renderer_zero_trail_length_draws_no_trail():
    vp = Viewport(size=(100, 100), half_width=3.0)
    r = SwarmRenderer(trail_length=0, viewport=vp)
    x = np.array([[1.0, 1.0]])
    r.record(x - 1.0)
    assert np.array_equal(r.frame(x), draw_swarm(x, viewport=vp))


def test_renderer_follow_keeps_swarm_in_view():
    r = SwarmRenderer(size=(100, 100), trail_length=3, follow=True)
    x = RNG.normal(size=(6, 3))
    for _ in range(30):
        x = x + np.array([1.0, -0.5, 0.0])
        r.record(x)
        r.frame(x, goal=np.zeros(3), goal_radius=0.5)
        px = r.viewport.to_pixels(x)
        assert np.all((px >= 0) & (px <= 99))


def test_renderer_fixed_view_when_not_following():
    r = SwarmRenderer(size=(100, 100), follow=False)
    r.frame(np.zeros((3, 2)))
    vp = r.viewport
    r.frame(np.full((3, 2), 50.0))
    assert r.viewport == vp
    r.reset()
    r.frame(np.full((3, 2), 50.0))
    assert r.viewport != vp


def test_renderer_handles_change_in_n():
    r = SwarmRenderer(size=(80, 80))
    r.record(np.zeros((3, 2)))
    r.record(np.ones((4, 2)))
    assert r.frame(np.ones((4, 2))).shape == (80, 80, 3)
    assert r.frame(np.ones((5, 2))).shape == (80, 80, 3)


def test_renderer_hundred_frames_run():
    r = SwarmRenderer(size=(200, 200), trail_length=30)
    x = RNG.normal(size=(100, 2))
    v = RNG.normal(size=(100, 2))
    for _ in range(100):
        x = x + 0.05 * v
        r.record(x)
        frame = r.frame(x, goal=np.array([3.0, 3.0]), goal_radius=1.0, velocities=v)
    assert frame.shape == (200, 200, 3)


def run_python(code: str, **env: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, **env},
    )


def test_show_on_headless_backend_warns_and_does_not_crash():
    out = run_python(
        """
        import warnings
        import numpy as np
        from swarm_envs.render import SwarmRenderer
        r = SwarmRenderer(size=(64, 64))
        f = r.frame(np.zeros((2, 2)))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            r.show(f)
            r.show(f)
        assert len(caught) == 1, caught
        assert "rgb_array" in str(caught[0].message)
        r.close()
        r.close()
        print("OK")
        """,
        MPLBACKEND="Agg",
    )
    assert out.returncode == 0, out.stderr
    assert "OK" in out.stdout


def test_import_loads_no_drawing_library():
    out = run_python(
        """
        import sys
        import swarm_envs.render
        heavy = [m for m in ("matplotlib", "PIL", "pygame", "imageio") if m in sys.modules]
        assert not heavy, heavy
        print("OK")
        """
    )
    assert out.returncode == 0, out.stderr
    assert "OK" in out.stdout


# --------------------------------------------------------------------------- GIF


def distinct_frames(n: int) -> list[np.ndarray]:
    vp = Viewport(size=(64, 48), half_width=3.0)
    return [draw_swarm(np.array([[-2.0 + 0.5 * i, 0.0]]), viewport=vp) for i in range(n)]


def test_write_gif_round_trip(tmp_path):
    iio = pytest.importorskip("imageio.v3")
    frames = distinct_frames(6)
    path = write_gif(frames, tmp_path / "sub" / "swarm.gif", fps=10)
    assert path.exists() and path.stat().st_size > 0
    back = iio.imread(path, index=None)
    assert back.shape[:3] == (6, 48, 64)
    assert iio.immeta(path)["loop"] == 0


def test_write_gif_subsamples(tmp_path):
    iio = pytest.importorskip("imageio.v3")
    frames = distinct_frames(9)
    every = write_gif(frames, tmp_path / "every.gif", every=3)  # 0, 3, 6 and the last (8)
    assert iio.imread(every, index=None).shape[0] == 4
    capped = write_gif(frames, tmp_path / "capped.gif", max_frames=5)
    assert iio.imread(capped, index=None).shape[0] == 5


@pytest.mark.parametrize(
    "frames, kwargs",
    [
        ([], {}),
        ([np.zeros((4, 4), np.uint8)], {}),
        ([np.zeros((4, 4, 3), np.uint8), np.zeros((5, 4, 3), np.uint8)], {}),
        ([np.zeros((4, 4, 3), np.uint8)], {"fps": 0}),
        ([np.zeros((4, 4, 3), np.uint8)], {"every": 0}),
    ],
)
def test_write_gif_bad_input(tmp_path, frames, kwargs):
    with pytest.raises(ValueError):
        write_gif(frames, tmp_path / "bad.gif", **kwargs)


def _ink(frame: np.ndarray, rows: slice, cols: slice) -> int:
    """Dark pixels (text, bars) in a region of ``frame``."""
    return int((frame[rows, cols].max(axis=-1) < 120).sum())


def test_annotate_writes_the_caption_and_a_scale_bar_of_a_round_length():
    vp = Viewport(half_width=10.0, size=(300, 300))
    frame = draw_swarm(np.array([[5.0, 5.0]]), viewport=vp)
    out = annotate(frame, vp, ["robust", "t = 1.0 s of 40.0 s"])
    assert out.shape == frame.shape and not np.shares_memory(out, frame)
    top_left, bottom_left = (slice(0, 40), slice(0, 120)), (slice(240, 300), slice(0, 120))
    assert _ink(frame, *top_left) == 0 and _ink(out, *top_left) > 50
    assert _ink(frame, *bottom_left) == 0 and _ink(out, *bottom_left) > 50
    assert scale_bar_length(vp) == 5.0  # a quarter of 20 units is 5
    assert scale_bar_length(Viewport(half_width=0.3, size=(300, 300))) == 0.1
    assert scale_bar_length(Viewport(half_width=300.0, size=(300, 300))) == 100.0
    # No viewport: the caption alone.
    assert _ink(annotate(frame, None, ["x"]), *bottom_left) == 0


def test_three_dimensional_frames_say_they_are_the_x_y_projection():
    corner = (slice(360, 400), slice(260, 400))
    flat = draw_swarm(np.zeros((3, 2)), viewport=Viewport(half_width=10.0))
    solid = draw_swarm(np.zeros((3, 3)), viewport=Viewport(half_width=10.0))
    assert _ink(flat, *corner) == 0 and _ink(solid, *corner) > 50
