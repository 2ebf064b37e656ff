"""Drawing a swarm to an RGB frame, fast enough to render every environment step.

Everything here rasterises with numpy directly: agents are antialiased filled discs
with a darker rim, the goal is a cross inside a ring of the goal radius (with a faint
tint inside), trails are polylines that fade with age, velocities are short heading
ticks, and a light grid marks world coordinates. No drawing library is imported by
this module; matplotlib (for a window, :meth:`SwarmRenderer.show`) and imageio (for
:func:`write_gif`) are imported inside the functions that need them, so importing
``swarm_envs.render`` (and every environment) stays cheap and works on headless
machines.

Three-dimensional positions are drawn as their x–y projection, and the frame says so
("x-y projection", bottom right). :func:`annotate` writes caption lines (a policy's
name, the time) and a scale bar into a frame, for GIFs whose camera follows the swarm
(Pillow's text, imported there). World coordinates have
y pointing up; a frame is a ``uint8`` array shaped ``(height, width, 3)``. A size is
always given as ``(width, height)`` in pixels, as in PIL and pygame.

Public interface:

- :class:`Viewport`: the world-to-pixel map (square world extent, y up).
- :func:`draw_swarm`: one frame from positions (and optionally goal, trails, velocities).
- :class:`SwarmRenderer`: what an environment holds: a trail buffer, a viewport policy
  (follow the swarm or stay fixed), a window for ``render_mode="human"``.
- :func:`write_gif`: frames to a small looping GIF.

Example:

>>> import numpy as np
>>> x = np.array([[0.0, 0.0], [1.0, 0.5], [-0.5, 1.0]])
>>> frame = draw_swarm(x, goal=np.array([3.0, 3.0]), goal_radius=1.0, size=(200, 120))
>>> frame.shape, frame.dtype
((120, 200, 3), dtype('uint8'))
"""

from __future__ import annotations

import math
import warnings
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "AGENT_COLOR",
    "BACKGROUND_COLOR",
    "GOAL_COLOR",
    "SwarmRenderer",
    "Viewport",
    "annotate",
    "draw_swarm",
    "scale_bar_length",
    "write_gif",
]

#: Background (white).
BACKGROUND_COLOR = (255, 255, 255)
#: Grid lines at "nice" world spacings (1, 2 or 5 times a power of ten).
GRID_COLOR = (234, 234, 236)
#: One-pixel frame around the image.
FRAME_COLOR = (180, 180, 184)
#: Default agent fill (matplotlib's ``tab:blue``); the rim is a darker shade of the fill.
AGENT_COLOR = (31, 119, 180)
#: Goal cross, goal-radius ring and the faint tint inside the ring (``tab:red``).
GOAL_COLOR = (214, 39, 40)

#: Opacity of the newest trail segment; older ones fade linearly to a tenth of it.
TRAIL_ALPHA = 0.55
#: Opacity of the tint inside the goal radius.
GOAL_FILL_ALPHA = 0.07
#: Pixel coordinates are clipped to this magnitude before rasterising, so agents far
#: outside a fixed viewport cost nothing and never overflow an integer conversion.
_PIXEL_CLIP = 1e7
#: Matplotlib backends that cannot open a window.
_NON_INTERACTIVE_BACKENDS = frozenset(
    {
        "agg",
        "cairo",
        "pdf",
        "pgf",
        "ps",
        "svg",
        "template",
        "module://matplotlib_inline.backend_inline",
    }
)


# --------------------------------------------------------------------------- validation


def _check_size(size: Sequence[int]) -> tuple[int, int]:
    """Return ``size`` as ``(width, height)`` ints, or raise ``ValueError``."""
    try:
        w, h = (int(s) for s in size)
    except (TypeError, ValueError):
        raise ValueError(f"size must be (width, height) in pixels, got {size!r}") from None
    if w < 1 or h < 1 or w > 16384 or h > 16384:
        raise ValueError(f"size must be (width, height) with each in [1, 16384], got {size!r}")
    return w, h


def _check_points(x: Any, name: str, *, ndim: int) -> np.ndarray:
    """Return ``x`` as float64 with last axis of length 2 or 3 and all values finite."""
    a = np.asarray(x, dtype=np.float64)
    if a.ndim != ndim or a.shape[-1] not in (2, 3):
        want = {1: "(d,)", 2: "(N, d)", 3: "(T, N, d)"}[ndim]
        raise ValueError(f"{name} must be shaped {want} with d = 2 or 3, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite (no NaN or inf)")
    return a


def _check_colors(colors: Any, n: int) -> np.ndarray:
    """Return per-agent colours as float32 ``(n, 3)`` in [0, 255]."""
    if colors is None:
        return np.broadcast_to(np.asarray(AGENT_COLOR, dtype=np.float32), (n, 3))
    c = np.asarray(colors)
    if c.shape == (3,):
        c = np.broadcast_to(c, (n, 3))
    if c.shape != (n, 3):
        raise ValueError(f"colors must be shaped (N, 3) = ({n}, 3) or (3,), got {c.shape}")
    c = c.astype(np.float32)
    if not np.all(np.isfinite(c)) or c.min() < 0 or c.max() > 255:
        raise ValueError("colors must be RGB values in [0, 255]")
    return c


# --------------------------------------------------------------------------- viewport


@dataclass(frozen=True)
class Viewport:
    """Map from world coordinates (y up) to pixel coordinates (row 0 at the top).

    The world extent is square in world units: the shorter side of the image spans
    ``2 * half_width`` world units around ``center``, and the longer side shows more
    at the same scale.

    Attributes:
        center: World point ``(x, y)`` drawn at the image centre.
        half_width: Half the world extent shown along the shorter image side, in
            [1e-300, 1e300] (keeps every derived length finite).
        size: Image size ``(width, height)`` in pixels.

    Example:
        >>> vp = Viewport(center=(0.0, 0.0), half_width=1.0, size=(100, 100))
        >>> vp.to_pixels(np.array([[0.0, 0.0], [1.0, 1.0]])).round(1).tolist()
        [[49.5, 49.5], [99.5, -0.5]]
    """

    center: tuple[float, float] = (0.0, 0.0)
    half_width: float = 1.0
    size: tuple[int, int] = (400, 400)

    def __post_init__(self) -> None:
        cx, cy = (float(c) for c in self.center)
        if not (math.isfinite(cx) and math.isfinite(cy)):
            raise ValueError(f"Viewport.center must be finite, got {self.center!r}")
        hw = float(self.half_width)
        if not (1e-300 <= hw <= 1e300):
            raise ValueError(
                f"Viewport.half_width must be in [1e-300, 1e300], got {self.half_width!r}"
            )
        object.__setattr__(self, "center", (cx, cy))
        object.__setattr__(self, "half_width", hw)
        object.__setattr__(self, "size", _check_size(self.size))

    @property
    def scale(self) -> float:
        """Pixels per world unit."""
        return min(self.size) / (2.0 * self.half_width)

    def to_pixels(self, points: np.ndarray) -> np.ndarray:
        """Pixel coordinates ``(column, row)`` of world points.

        Pixel ``(i, j)`` (row, column) covers ``[j - 0.5, j + 0.5] x [i - 0.5, i + 0.5]``.
        Coordinates far outside the image are clipped to ``±1e7`` pixels.

        Args:
            points: World points shaped ``(..., d)``, d >= 2; only x and y are used.

        Returns:
            Float64 array shaped ``(..., 2)``.
        """
        p = np.asarray(points, dtype=np.float64)
        w, h = self.size
        s = self.scale
        out = np.empty((*p.shape[:-1], 2), dtype=np.float64)
        with np.errstate(over="ignore", invalid="ignore"):
            out[..., 0] = (w / 2 - 0.5) + (p[..., 0] - self.center[0]) * s
            out[..., 1] = (h / 2 - 0.5) - (p[..., 1] - self.center[1]) * s
        np.clip(out, -_PIXEL_CLIP, _PIXEL_CLIP, out=out)
        return out

    @classmethod
    def fit(
        cls,
        points: np.ndarray,
        goal: np.ndarray | None = None,
        margin: float = 0.1,
        min_half_width: float = 1.0,
        *,
        goal_radius: float | None = None,
        size: Sequence[int] = (400, 400),
    ) -> Viewport:
        """Viewport centred on the bounding box of ``points`` (and the goal).

        Args:
            points: World points shaped ``(..., d)`` (e.g. ``(N, d)`` or ``(T, N, d)``).
            goal: Optional goal ``(d,)`` to keep in view.
            margin: Fraction of the content's extent added on each side.
            min_half_width: Smallest half-width in world units (used when all points
                coincide, e.g. ``N = 1``).
            goal_radius: If given with ``goal``, the whole goal circle is kept in view.
            size: Image size ``(width, height)`` in pixels.

        Returns:
            The fitted :class:`Viewport`.

        Raises:
            ValueError: non-finite points, ``margin < 0`` or ``min_half_width`` outside
                [1e-300, 1e300].

        Example:
            >>> vp = Viewport.fit(np.array([[0.0, 0.0], [2.0, 1.0]]), margin=0.0)
            >>> vp.center, vp.half_width
            ((1.0, 0.5), 1.0)
        """
        if not (math.isfinite(margin) and margin >= 0):
            raise ValueError(f"margin must be finite and >= 0, got {margin!r}")
        if not (1e-300 <= min_half_width <= 1e300):
            raise ValueError(f"min_half_width must be in [1e-300, 1e300], got {min_half_width!r}")
        p = np.asarray(points, dtype=np.float64)
        if p.ndim < 1 or p.shape[-1] < 2:
            raise ValueError(f"points must be shaped (..., d) with d >= 2, got shape {p.shape}")
        p = p.reshape(-1, p.shape[-1])[:, :2]
        extra = []
        if goal is not None:
            g = _check_points(goal, "goal", ndim=1)[:2]
            r = 0.0 if goal_radius is None else abs(float(goal_radius))
            extra = [g - r, g + r]
        if extra:
            p = np.concatenate([p, np.stack(extra)])
        if p.shape[0] == 0:
            return cls(center=(0.0, 0.0), half_width=min_half_width, size=_check_size(size))
        if not np.all(np.isfinite(p)):
            raise ValueError("points must be finite (no NaN or inf)")
        lo, hi = p.min(axis=0), p.max(axis=0)
        with np.errstate(over="ignore", invalid="ignore"):
            center = lo / 2 + hi / 2
            half = float(np.max(hi / 2 - lo / 2)) * (1.0 + 2.0 * margin)
        if not math.isfinite(half) or half > 1e300:
            half = 1e300  # keeps every derived length finite
        return cls(
            center=(float(center[0]), float(center[1])),
            half_width=max(half, min_half_width),
            size=_check_size(size),
        )


# --------------------------------------------------------------------------- rasteriser


class _Canvas:
    """uint8 RGB canvas with antialiased, alpha-blended primitives.

    Pixels are stored as three colour planes (row-major, so 1-D gathers and scatters
    stay fast) with ``pad`` pixels of hidden margin on every side: a primitive that
    pokes a few pixels out of the image writes into the margin, so no per-pixel bounds
    checks are needed. Primitives produce flat indices into the padded planes with a
    coverage per sample and hand them to :meth:`blend`.
    """

    def __init__(self, size: tuple[int, int], background: Sequence[int], pad: int = 16) -> None:
        self.w, self.h = size
        self.pad = int(pad)
        self.wp, self.hp = self.w + 2 * self.pad, self.h + 2 * self.pad
        self.planes = np.empty((3, self.wp * self.hp), dtype=np.uint8)
        self.planes[:] = np.asarray(background, dtype=np.uint8)[:, None]

    def image(self) -> np.ndarray:
        """The visible image as a view ``(3, h, w)`` (writes go to the canvas)."""
        p = self.pad
        return self.planes.reshape(3, self.hp, self.wp)[:, p : p + self.h, p : p + self.w]

    def flat(self, col: np.ndarray, row: np.ndarray) -> np.ndarray:
        """Flat index into the padded planes of image pixel ``(col, row)``."""
        return (row + self.pad) * self.wp + (col + self.pad)

    def blend(self, idx: np.ndarray, alpha: np.ndarray, color: np.ndarray) -> None:
        """Blend ``color`` over flat pixels ``idx`` with per-sample ``alpha`` in [0, 1].

        Where several samples hit one pixel the largest alpha is used (no double
        darkening) and, for per-sample colours ``(M, 3)``, the last sample's colour wins.
        """
        if idx.size == 0:
            return
        a = np.zeros(self.wp * self.hp, dtype=np.float32)
        np.maximum.at(a, idx, alpha.astype(np.float32, copy=False))
        touched = np.flatnonzero(a > 0)
        if touched.size == 0:
            return
        at = a[touched]
        color = np.asarray(color, dtype=np.float32)
        cbuf = None
        if color.ndim == 2:
            cbuf = np.zeros((3, self.wp * self.hp), dtype=np.float32)
            cbuf[:, idx] = color.T
        for ch in range(3):
            plane = self.planes[ch]
            g = plane[touched].astype(np.float32)
            c = color[ch] if cbuf is None else cbuf[ch, touched]
            g += (c - g) * at + np.float32(0.5)
            plane[touched] = g  # truncating x + 0.5 rounds (values lie in [0, 255.5])

    def discs(
        self,
        centers: np.ndarray,
        radius: float,
        colors: np.ndarray,
        alpha: float = 1.0,
    ) -> None:
        """Filled antialiased discs of ``radius`` px (< pad - 2) at pixel ``centers``.

        ``colors`` is ``(3,)`` or one row per disc. Discs wholly outside the image
        are skipped.
        """
        k = math.ceil(radius + 0.5)
        vis = (
            (centers[:, 0] > -k - 1)
            & (centers[:, 0] < self.w + k)
            & (centers[:, 1] > -k - 1)
            & (centers[:, 1] < self.h + k)
        )
        if radius <= 0 or not vis.any():
            return
        c = centers[vis]
        off = np.arange(-k, k + 1)
        oy, ox = np.meshgrid(off, off, indexing="ij")
        keep = ox * ox + oy * oy <= (radius + 1.5) ** 2
        oy, ox = oy[keep], ox[keep]
        base = np.rint(c).astype(np.int64)
        fx = ((base[:, 0:1] - c[:, 0:1]) + ox).astype(np.float32)
        fy = ((base[:, 1:2] - c[:, 1:2]) + oy).astype(np.float32)
        cov = np.float32(radius + 0.5) - np.sqrt(fx * fx + fy * fy)
        np.clip(cov, 0.0, 1.0, out=cov)
        idx = self.flat(base[:, 0:1] + ox, base[:, 1:2] + oy)
        col = colors
        if np.ndim(colors) == 2:
            col = np.repeat(np.asarray(colors)[vis], ox.size, axis=0)
        self.blend(idx.ravel(), (cov * np.float32(alpha)).ravel(), col)

    def lines(
        self,
        p0: np.ndarray,
        p1: np.ndarray,
        width: float,
        colors: np.ndarray,
        alpha: float | np.ndarray = 1.0,
    ) -> None:
        """Antialiased segments ``p0[i] -> p1[i]`` (pixel coordinates) of ``width`` px.

        Segments are clipped to the image (Liang–Barsky), then drawn Wu-style: one
        sample per pixel along the major axis, and across it the pixels within the
        line's half-width (measured along the minor axis) with box-filter coverage.
        ``colors`` is ``(3,)`` or one row per segment; ``alpha`` a scalar or one value
        per segment. ``width`` must stay below ``pad / 2``.
        """
        if p0.shape[0] == 0:
            return
        m = width / 2 + 1.0
        lo = np.array([-m, -m])
        hi = np.array([self.w - 1 + m, self.h - 1 + m])
        if np.all((p0 >= lo) & (p0 <= hi) & (p1 >= lo) & (p1 <= hi)):
            sel = np.arange(p0.shape[0])  # common case: nothing to clip
            a, b = p0, p1
        else:
            d = p1 - p0
            t0 = np.zeros(p0.shape[0])
            t1 = np.ones(p0.shape[0])
            keep = np.ones(p0.shape[0], dtype=bool)
            with np.errstate(divide="ignore", invalid="ignore"):
                for ax in (0, 1):
                    for p, q in ((-d[:, ax], p0[:, ax] - lo[ax]), (d[:, ax], hi[ax] - p0[:, ax])):
                        r = q / p
                        keep &= ~((p == 0) & (q < 0))
                        t0 = np.where(p < 0, np.maximum(t0, r), t0)
                        t1 = np.where(p > 0, np.minimum(t1, r), t1)
            keep &= t0 <= t1
            sel = np.flatnonzero(keep)
            if sel.size == 0:
                return
            a = p0[sel] + t0[sel, None] * d[sel]
            b = p0[sel] + t1[sel, None] * d[sel]
        # Major axis: x (0) or y (1) per segment; orient each segment along +major.
        dd = b - a
        is_y = np.abs(dd[:, 1]) > np.abs(dd[:, 0])
        major = is_y.astype(np.int64)
        rows = np.arange(sel.size)
        a_maj, b_maj = a[rows, major], b[rows, major]
        a_min, b_min = a[rows, 1 - major], b[rows, 1 - major]
        flip = b_maj < a_maj
        a_maj, b_maj = np.where(flip, b_maj, a_maj), np.where(flip, a_maj, b_maj)
        a_min, b_min = np.where(flip, b_min, a_min), np.where(flip, a_min, b_min)
        span = b_maj - a_maj
        with np.errstate(divide="ignore", invalid="ignore"):
            slope = np.where(span > 0, (b_min - a_min) / span, 0.0)
        half = (width / 2) * np.sqrt(1.0 + slope * slope)  # half-width along the minor axis
        # One sample per pixel column (row) along the major axis.
        s0 = np.ceil(a_maj - 0.5).astype(np.int64)
        n = np.floor(b_maj + 0.5).astype(np.int64) - s0 + 1
        seg = np.repeat(rows, n)
        if seg.size == 0:
            return
        s = np.arange(seg.size) - np.repeat(np.cumsum(n) - n - s0, n)
        off_a = s - a_maj[seg]
        mid = a_min[seg] + slope[seg] * np.clip(off_a, 0.0, span[seg])
        # Ends fade so a segment of length L carries about L + width pixels of ink.
        end_cov = np.minimum(off_a, b_maj[seg] - s).astype(np.float32)
        end_cov += np.float32(0.5 + width / 2)
        np.clip(end_cov, 0.0, 1.0, out=end_cov)
        if np.ndim(alpha) == 0:
            end_cov *= np.float32(alpha)
        else:
            end_cov *= np.asarray(alpha, dtype=np.float32)[sel[seg]]
        base = np.rint(mid).astype(np.int64)
        frac = (mid - base).astype(np.float32)
        k = math.floor(float(half.max()) + 1.0 - 1e-9)
        offs = np.arange(-k, k + 1)
        cov = (half[seg] + 0.5).astype(np.float32)[:, None] - np.abs(
            offs.astype(np.float32) - frac[:, None]
        )
        np.clip(cov, 0.0, 1.0, out=cov)
        cov *= end_cov[:, None]
        # Flat index of (major s, minor base) and the index step of one minor pixel.
        sy = is_y[seg]
        idx0 = np.where(sy, self.flat(base, s), self.flat(s, base))
        step = np.where(sy, 1, self.wp)
        idx = idx0[:, None] + offs * step[:, None]
        col = colors
        if np.ndim(colors) == 2:
            col = np.repeat(np.asarray(colors)[sel[seg]], offs.size, axis=0)
        self.blend(idx.ravel(), cov.ravel(), col)

    def ring(
        self,
        center: np.ndarray,
        radius: float,
        width: float,
        color: np.ndarray,
        fill_alpha: float = 0.0,
    ) -> None:
        """Circle of ``radius`` px (an antialiased polyline), optionally tinting inside.

        The tint is a flat blend with ``fill_alpha`` over the pixels whose centres lie
        inside the circle (its edge is hidden under the ring).
        """
        cx, cy = float(center[0]), float(center[1])
        if radius <= 0:
            return
        r_out = radius + width / 2 + 1.0
        x0, x1 = max(math.floor(cx - r_out), 0), min(math.ceil(cx + r_out), self.w - 1)
        y0, y1 = max(math.floor(cy - r_out), 0), min(math.ceil(cy + r_out), self.h - 1)
        if x0 > x1 or y0 > y1:
            return
        if fill_alpha > 0:
            dx = (np.arange(x0, x1 + 1) - cx) ** 2
            dy = (np.arange(y0, y1 + 1) - cy) ** 2
            inside = dy[:, None] + dx[None, :] <= radius * radius
            if inside.any():
                sub = self.image()[:, y0 : y1 + 1, x0 : x1 + 1]
                levels = np.arange(256, dtype=np.float32)
                for ch in range(3):
                    lut = levels + (np.float32(color[ch]) - levels) * np.float32(fill_alpha)
                    lut = (lut + np.float32(0.5)).astype(np.uint8)
                    plane = sub[ch]
                    plane[inside] = lut[plane[inside]]
        # Polyline with segments of about 3 px (at most 4096 of them).
        n_seg = int(np.clip(math.ceil(2 * math.pi * radius / 3.0), 24, 4096))
        ang = np.linspace(0.0, 2 * math.pi, n_seg + 1)
        pts = np.stack([cx + radius * np.cos(ang), cy + radius * np.sin(ang)], axis=1)
        self.lines(pts[:-1], pts[1:], width, color)

    def grid(self, vp: Viewport, color: Sequence[int], min_spacing_px: float = 24.0) -> None:
        """Vertical and horizontal lines at a "nice" world spacing."""
        span = 2.0 * vp.half_width * (max(self.w, self.h) / min(self.w, self.h))
        raw = span / 6.0
        step = 10.0 ** math.floor(math.log10(raw))
        for f in (1.0, 2.0, 5.0, 10.0):
            if f * step >= raw:
                step *= f
                break
        if step * vp.scale < min_spacing_px:
            return
        col = np.asarray(color, dtype=np.uint8)
        img = self.image()
        for axis, n_px, c0 in ((0, self.w, vp.center[0]), (1, self.h, vp.center[1])):
            half = n_px / (2.0 * vp.scale)
            k0 = math.floor((c0 - half) / step)
            ks = k0 + np.arange(int(2 * half / step) + 3)
            world = np.zeros((ks.size, 2))
            world[:, axis] = ks * step
            world[:, 1 - axis] = vp.center[1 - axis]
            pix = np.rint(vp.to_pixels(world)[:, axis]).astype(np.int64)
            pix = pix[(pix >= 0) & (pix < n_px)]
            for ch in range(3):
                if axis == 0:
                    img[ch][:, pix] = col[ch]
                else:
                    img[ch][pix, :] = col[ch]

    def border(self, color: Sequence[int]) -> None:
        """One-pixel frame around the image."""
        img = self.image()
        for ch, v in enumerate(np.asarray(color, dtype=np.uint8)):
            img[ch, 0, :] = img[ch, -1, :] = v
            img[ch, :, 0] = img[ch, :, -1] = v

    def to_uint8(self) -> np.ndarray:
        """The canvas as a new ``uint8`` array ``(height, width, 3)``."""
        out = np.empty((self.h, self.w, 3), dtype=np.uint8)
        img = self.image()
        for ch in range(3):
            out[:, :, ch] = img[ch]
        return out


def _default_agent_radius(size: tuple[int, int], n: int) -> float:
    """Agent disc radius in pixels: about 1.3 % of the shorter side, smaller for big N."""
    r = 0.013 * min(size)
    if n > 200:
        r *= math.sqrt(200.0 / n)
    return float(np.clip(r, 3.0, 9.0))


def draw_swarm(
    x: np.ndarray,
    *,
    goal: np.ndarray | None = None,
    goal_radius: float | None = None,
    trails: np.ndarray | None = None,
    velocities: np.ndarray | None = None,
    viewport: Viewport | None = None,
    size: Sequence[int] = (400, 400),
    colors: np.ndarray | None = None,
    agent_radius_px: float | None = None,
    grid: bool = True,
) -> np.ndarray:
    """Draw a swarm (x–y projection) to an RGB frame.

    Drawing order, back to front: white background and light grid; goal-radius ring
    with a faint tint inside; trails (older segments fainter); agents (filled discs with
    a darker rim); heading ticks; goal cross; one-pixel frame.

    Args:
        x: Positions shaped ``(N, d)``, d = 2 or 3 (3-D is drawn as its x–y projection).
            ``N = 0`` draws an empty scene.
        goal: Optional goal position ``(d,)``, drawn as a cross.
        goal_radius: Optional radius (world units) drawn as a ring around ``goal``;
            ignored without ``goal``.
        trails: Optional past positions ``(T, N, d)``, oldest first. Each agent's trail
            is the polyline ``trails[0], ..., trails[T-1], x``; opacity grows linearly
            from about ``TRAIL_ALPHA / 10`` (oldest) to :data:`TRAIL_ALPHA` (newest).
        velocities: Optional ``(N, d)``; each moving agent gets a tick from its centre
            in the direction of its x–y velocity (fixed length, independent of speed).
        viewport: World-to-pixel map. If None, one is fitted to ``x``, ``trails`` and
            the goal circle with :meth:`Viewport.fit`; its ``size`` then comes from
            ``size``. A given viewport's own ``size`` wins over ``size``.
        size: Image size ``(width, height)`` in pixels when ``viewport`` is None.
        colors: Optional agent colours, ``(N, 3)`` (or one ``(3,)`` colour), values in
            [0, 255]. Default :data:`AGENT_COLOR`.
        agent_radius_px: Agent disc radius in pixels (default: about 1.3 % of the
            shorter image side, smaller for N > 200).
        grid: Draw the light coordinate grid.

    Returns:
        ``uint8`` array shaped ``(height, width, 3)``.

    Raises:
        ValueError: badly shaped or non-finite inputs.

    Example:
        >>> f = draw_swarm(np.zeros((1, 3)), goal=np.ones(3), goal_radius=0.5)
        >>> f.shape, f.dtype, len(np.unique(f.reshape(-1, 3), axis=0)) > 3
        ((400, 400, 3), dtype('uint8'), True)
    """
    pos = _check_points(x, "x", ndim=2)
    n = pos.shape[0]
    g = None if goal is None else _check_points(goal, "goal", ndim=1)
    tr = None
    if trails is not None:
        tr = _check_points(trails, "trails", ndim=3)
        if tr.shape[1] != n:
            raise ValueError(f"trails must be shaped (T, N, d) with N = {n}, got {tr.shape}")
    vel = None
    if velocities is not None:
        vel = _check_points(velocities, "velocities", ndim=2)
        if vel.shape[0] != n:
            raise ValueError(f"velocities must be shaped (N, d) with N = {n}, got {vel.shape}")
    gr = None
    if goal_radius is not None and g is not None:
        gr = float(goal_radius)
        if not (math.isfinite(gr) and gr >= 0):
            raise ValueError(f"goal_radius must be finite and >= 0, got {goal_radius!r}")
    cols = _check_colors(colors, n)
    uniform = n == 0 or bool(np.all(cols == cols[0]))  # one colour: cheaper blending

    if viewport is None:
        content = (
            pos[:, :2] if tr is None else np.concatenate([pos[:, :2], tr[..., :2].reshape(-1, 2)])
        )
        viewport = Viewport.fit(content, g, goal_radius=gr, size=size)
    vp = viewport
    if agent_radius_px is None:
        radius = _default_agent_radius(vp.size, n)
    else:
        radius = float(agent_radius_px)
        if not (0 < radius <= 64):
            raise ValueError(f"agent_radius_px must be in (0, 64], got {agent_radius_px!r}")
    # Hidden margin: wide enough for a disc or the goal cross poking out of the image.
    canvas = _Canvas(vp.size, BACKGROUND_COLOR, pad=max(16, 2 * math.ceil(radius + 0.5) + 8))
    if grid:
        canvas.grid(vp, GRID_COLOR)

    goal_px = None if g is None else vp.to_pixels(g[:2])
    goal_rgb = np.asarray(GOAL_COLOR, dtype=np.float32)
    if goal_px is not None and gr is not None and gr > 0:
        canvas.ring(goal_px, gr * vp.scale, 2.0, goal_rgb, fill_alpha=GOAL_FILL_ALPHA)

    pos_px = vp.to_pixels(pos[:, :2])

    if tr is not None and tr.shape[0] > 0 and n > 0:
        path = np.concatenate([vp.to_pixels(tr[..., :2]), pos_px[None]])  # (T+1, N, 2)
        n_seg = path.shape[0] - 1
        age = np.arange(1, n_seg + 1) / n_seg  # (0, 1], oldest -> newest
        age_alpha = TRAIL_ALPHA * (0.1 + 0.9 * age)
        p0 = path[:-1].reshape(-1, 2)
        p1 = path[1:].reshape(-1, 2)
        seg_alpha = np.repeat(age_alpha, n)
        seg_color = cols[0] if uniform else np.tile(cols, (n_seg, 1))
        canvas.lines(p0, p1, 1.4, seg_color, seg_alpha)

    fill = (cols[0] if n else np.asarray(AGENT_COLOR, np.float32)) if uniform else cols
    rim = fill * 0.6
    canvas.discs(pos_px, radius, rim)
    canvas.discs(pos_px, max(radius - 1.3, 0.5), fill)

    if vel is not None and n > 0:
        v = vel[:, :2] * np.array([1.0, -1.0])  # y up in the world, down in pixels
        speed = np.hypot(v[:, 0], v[:, 1])
        moving = speed > 0
        if moving.any():
            u = v[moving] / speed[moving, None]
            start = pos_px[moving]
            end = start + u * (radius + max(4.0, 0.8 * radius))
            canvas.lines(start, end, max(1.2, 0.3 * radius), rim if uniform else rim[moving])

    if goal_px is not None:
        arm = max(4.0, 1.3 * radius)
        diag = np.array([[1.0, 1.0], [1.0, -1.0]]) * arm
        canvas.lines(goal_px - diag, goal_px + diag, max(2.0, 0.55 * radius), goal_rgb)

    canvas.border(FRAME_COLOR)
    frame = canvas.to_uint8()
    if x.shape[-1] == 3:
        _text(frame, ["x-y projection"], corner="bottom right")
    return frame


# --------------------------------------------------------------------------- annotations

#: Caption text and scale bar colour (dark grey), and the box behind them.
TEXT_COLOR = (40, 40, 44)
_TEXT_BOX = (255, 255, 255, 200)


def _font(height: int) -> Any:
    from PIL import ImageFont

    return ImageFont.load_default(size=max(9, round(height / 28)))


def _text(frame: np.ndarray, lines: Sequence[str], *, corner: str = "top left") -> None:
    """Write ``lines`` into ``frame`` (in place) at ``corner``, on a light box."""
    if not lines:
        return
    from PIL import Image, ImageDraw

    h, w = frame.shape[:2]
    font = _font(min(h, w))
    image = Image.fromarray(frame).convert("RGBA")
    layer = Image.new("RGBA", image.size, (0, 0, 0, 0))
    draw = ImageDraw.Draw(layer)
    text = "\n".join(lines)
    left, top, right, bottom = draw.multiline_textbbox((0, 0), text, font=font, spacing=2)
    pad = 3
    tw, th = right - left + 2 * pad, bottom - top + 2 * pad
    x0 = 4 if "left" in corner else w - 4 - tw
    y0 = 4 if "top" in corner else h - 4 - th
    draw.rectangle((x0, y0, x0 + tw, y0 + th), fill=_TEXT_BOX)
    draw.multiline_text(
        (x0 + pad - left, y0 + pad - top), text, font=font, fill=TEXT_COLOR, spacing=2
    )
    frame[...] = np.asarray(Image.alpha_composite(image, layer).convert("RGB"))


def scale_bar_length(viewport: Viewport, fraction: float = 0.25) -> float:
    """A round world length (1, 2 or 5 times a power of ten) near ``fraction`` of the
    frame's width.

    >>> scale_bar_length(Viewport(half_width=10.0, size=(400, 400)))
    5.0
    """
    target = fraction * viewport.size[0] / viewport.scale
    power = 10.0 ** math.floor(math.log10(target))
    return max(m * power for m in (1.0, 2.0, 5.0) if m * power <= target)


def annotate(frame: np.ndarray, viewport: Viewport | None, lines: Sequence[str] = ()) -> np.ndarray:
    """``frame`` with caption ``lines`` at the top left and, given the frame's
    ``viewport``, a scale bar at the bottom left labelled with its world length.

    Returns a new array; ``frame`` is left as it was.

    >>> vp = Viewport(half_width=10.0, size=(200, 200))
    >>> out = annotate(draw_swarm(np.zeros((3, 2)), viewport=vp), vp, ["potential", "t = 1.0 s"])
    >>> out.shape, out.dtype
    ((200, 200, 3), dtype('uint8'))
    """
    out = np.array(frame, dtype=np.uint8, copy=True)
    _text(out, list(lines), corner="top left")
    if viewport is not None:
        length = scale_bar_length(viewport)
        px = max(1, round(length * viewport.scale))
        h = out.shape[0]
        label = f"{length:g}"
        _text(out, [f"{label} {'unit' if length == 1 else 'units'}"], corner="bottom left")
        row = h - 4 - round(min(out.shape[:2]) / 28) - 12
        x0 = 8
        out[row - 1 : row + 2, x0 : x0 + px] = TEXT_COLOR
        out[row - 4 : row + 5, x0 : x0 + 2] = TEXT_COLOR
        out[row - 4 : row + 5, x0 + px - 2 : x0 + px] = TEXT_COLOR
    return out


# --------------------------------------------------------------------------- renderer


class SwarmRenderer:
    """Per-environment rendering state: trail buffer, viewport policy, window.

    An environment creates one, calls :meth:`reset` on reset, :meth:`record` after
    each step, :meth:`frame` in ``render()`` (``render_mode="rgb_array"`` returns it;
    ``"human"`` passes it to :meth:`show`), and :meth:`close` in ``close()``.

    Viewport policy:

    - ``viewport`` given: fixed, never changes.
    - ``follow=True``: every frame the view eases towards the box around the swarm,
      its trail and the goal circle (``smoothing`` is the fraction of the way moved
      per frame) but always grows at once to keep all of them in view.
    - ``follow=False``: fitted to the first frame after :meth:`reset` (with twice the
      margin) and then fixed; agents that leave it are not drawn.

    Args:
        size: Frame size ``(width, height)`` in pixels.
        trail_length: Number of past recorded positions drawn as a trail (0: none).
        follow: Viewport policy, see above.
        viewport: Optional fixed :class:`Viewport` (its size overrides ``size``).
        margin: Margin passed to :meth:`Viewport.fit`.
        min_half_width: Smallest half-width (world units) of a fitted view.
        smoothing: Easing factor in (0, 1] for ``follow=True`` (1: no easing).

    Example:
        >>> r = SwarmRenderer(size=(160, 120), trail_length=5)
        >>> for t in range(3):
        ...     r.record(np.array([[0.1 * t, 0.0], [0.0, 0.2 * t]]))
        >>> r.frame(np.array([[0.3, 0.0], [0.0, 0.6]]), goal=np.array([1.0, 1.0])).shape
        (120, 160, 3)
        >>> r.close(); r.close()
    """

    def __init__(
        self,
        size: Sequence[int] = (400, 400),
        trail_length: int = 30,
        follow: bool = True,
        *,
        viewport: Viewport | None = None,
        margin: float = 0.1,
        min_half_width: float = 1.0,
        smoothing: float = 0.25,
    ) -> None:
        self.size = _check_size(size if viewport is None else viewport.size)
        if int(trail_length) != trail_length or trail_length < 0:
            raise ValueError(f"trail_length must be an integer >= 0, got {trail_length!r}")
        if not (0 < smoothing <= 1):
            raise ValueError(f"smoothing must be in (0, 1], got {smoothing!r}")
        if not (math.isfinite(margin) and margin >= 0):
            raise ValueError(f"margin must be finite and >= 0, got {margin!r}")
        if not (1e-300 <= min_half_width <= 1e300):
            raise ValueError(f"min_half_width must be in [1e-300, 1e300], got {min_half_width!r}")
        self.trail_length = int(trail_length)
        self.follow = bool(follow)
        self.margin = float(margin)
        self.min_half_width = float(min_half_width)
        self.smoothing = float(smoothing)
        self._fixed = viewport
        self._viewport: Viewport | None = viewport
        self._trail: deque[np.ndarray] = deque(maxlen=max(self.trail_length, 1))
        self._fig: Any = None
        self._image: Any = None
        self._display_failed = False

    @property
    def viewport(self) -> Viewport | None:
        """The viewport of the last frame (None before the first frame)."""
        return self._viewport

    def reset(self) -> None:
        """Forget the trail and (unless fixed) the viewport; the window stays open."""
        self._trail.clear()
        self._viewport = self._fixed

    def record(self, x: np.ndarray) -> None:
        """Append positions ``(N, d)`` to the trail (the oldest entry drops out).

        A change in N clears the trail first.
        """
        if self.trail_length == 0:
            return
        pos = _check_points(x, "x", ndim=2)[:, :2].copy()
        if self._trail and self._trail[-1].shape != pos.shape:
            self._trail.clear()
        self._trail.append(pos)

    def _update_viewport(
        self, x: np.ndarray, trails: np.ndarray | None, goal: np.ndarray | None, gr: float | None
    ) -> Viewport:
        if self._fixed is not None:
            return self._fixed
        if not self.follow and self._viewport is not None:
            return self._viewport
        content = x[:, :2] if trails is None else np.concatenate([x[:, :2], trails.reshape(-1, 2)])
        margin = self.margin if self.follow else 2.0 * self.margin
        target = Viewport.fit(
            content, goal, margin, self.min_half_width, goal_radius=gr, size=self.size
        )
        old = self._viewport
        if old is None or not self.follow:
            return target
        s = self.smoothing
        c = np.array(old.center) + s * (np.array(target.center) - np.array(old.center))
        h = old.half_width + s * (target.half_width - old.half_width)
        pts = content
        if goal is not None:
            r = 0.0 if gr is None else gr
            g = np.asarray(goal, dtype=np.float64)[:2]
            pts = np.concatenate([pts, [g - r, g + r]])
        if pts.shape[0]:
            with np.errstate(over="ignore", invalid="ignore"):
                need = float(np.max(np.abs(pts - c))) * (1.0 + self.margin)
            if math.isfinite(need):
                h = max(h, need)
        return Viewport(
            center=(float(c[0]), float(c[1])),
            half_width=max(h, self.min_half_width),
            size=self.size,
        )

    def frame(
        self,
        x: np.ndarray,
        goal: np.ndarray | None = None,
        goal_radius: float | None = None,
        velocities: np.ndarray | None = None,
        *,
        colors: np.ndarray | None = None,
    ) -> np.ndarray:
        """Draw the current state with the recorded trail.

        Args:
            x: Positions ``(N, d)``.
            goal: Optional goal ``(d,)``.
            goal_radius: Optional goal radius (world units).
            velocities: Optional ``(N, d)`` drawn as heading ticks.
            colors: Optional per-agent colours ``(N, 3)``.

        Returns:
            ``uint8`` array shaped ``(height, width, 3)``.
        """
        pos = _check_points(x, "x", ndim=2)
        trails = None
        if self.trail_length and self._trail and self._trail[-1].shape == pos[:, :2].shape:
            trails = np.stack(self._trail)
        gr = None
        if goal is not None and goal_radius is not None:
            gr = float(goal_radius)
        g = None if goal is None else _check_points(goal, "goal", ndim=1)
        self._viewport = self._update_viewport(pos, trails, g, gr)
        return draw_swarm(
            pos,
            goal=g,
            goal_radius=gr,
            trails=trails,
            velocities=velocities,
            viewport=self._viewport,
            colors=colors,
        )

    def show(self, frame: np.ndarray) -> None:
        """Display ``frame`` in a window (for ``render_mode="human"``).

        Uses matplotlib in interactive mode, imported here. Without a display (a
        non-interactive backend such as Agg, or a window that cannot be opened) this
        warns once with a :class:`UserWarning` explaining the problem and returns
        without showing anything; it never raises for that reason.
        """
        if self._display_failed:
            return
        try:
            import matplotlib
            import matplotlib.pyplot as plt

            backend = str(matplotlib.get_backend()).lower()
            if backend in _NON_INTERACTIVE_BACKENDS:
                raise RuntimeError(f"matplotlib backend {backend!r} cannot open a window")
            if self._fig is None or not plt.fignum_exists(self._fig.number):
                plt.ion()
                w, h = frame.shape[1], frame.shape[0]
                fig = plt.figure(figsize=(w / 100, h / 100), dpi=100)
                ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
                ax.set_axis_off()
                self._image = ax.imshow(frame, interpolation="nearest")
                manager = getattr(fig.canvas, "manager", None)
                if manager is not None:
                    manager.set_window_title("swarm_envs")
                self._fig = fig
                plt.show(block=False)
            else:
                self._image.set_data(frame)
            self._fig.canvas.draw_idle()
            plt.pause(0.001)
        except Exception as err:  # no display, no GUI toolkit, ...
            self._display_failed = True
            warnings.warn(
                f'render_mode="human" could not open a window ({err}). Frames are not '
                "shown. Set a GUI matplotlib backend (e.g. MPLBACKEND=TkAgg) on a machine "
                'with a display, or use render_mode="rgb_array".',
                UserWarning,
                stacklevel=2,
            )

    def close(self) -> None:
        """Close the window if one is open; safe to call any number of times."""
        fig, self._fig, self._image = self._fig, None, None
        if fig is not None:
            try:
                import matplotlib.pyplot as plt

                plt.close(fig)
            except Exception:  # pragma: no cover - closing must never raise
                pass


# --------------------------------------------------------------------------- GIF


def write_gif(
    frames: Sequence[np.ndarray],
    path: str | Path,
    fps: float = 20,
    *,
    every: int = 1,
    max_frames: int | None = 300,
) -> Path:
    """Write frames to a looping GIF (imageio, imported here).

    Keeping files small: the size grows with frame count times frame area. Fading
    trails change every frame, so each frame costs roughly 25-30 kB at 400x400 with
    100 agents and 50-step trails (about 3.4 MB for 120 frames), about a third of
    that at 240x240, and only a few kB when little moves. So render GIF frames at a
    small ``size`` (240-320 px), keep every ``every``-th frame, and cap the count with
    ``max_frames`` (evenly spaced; the last frame is always kept). ``fps`` is the
    playback rate of the frames written, so subsampling speeds playback up. GIF
    stores delays in 1/100 s, so fps above 50 is not honoured by most viewers.
    Identical consecutive frames may be merged into one longer frame by the encoder.

    Args:
        frames: Sequence of ``uint8`` frames ``(H, W, 3)``, all the same shape.
        path: Output file (parent folders are created).
        fps: Playback frames per second (> 0).
        every: Keep every ``every``-th frame (>= 1).
        max_frames: Upper bound on frames written (None: no bound).

    Returns:
        The path written.

    Raises:
        ValueError: no frames, frames of different shapes or not ``(H, W, 3)``, bad
            ``fps``, ``every`` or ``max_frames``.
    """
    if not (math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be finite and > 0, got {fps!r}")
    if int(every) != every or every < 1:
        raise ValueError(f"every must be an integer >= 1, got {every!r}")
    if max_frames is not None and (int(max_frames) != max_frames or max_frames < 1):
        raise ValueError(f"max_frames must be an integer >= 1 or None, got {max_frames!r}")
    frames = list(frames)
    if not frames:
        raise ValueError("frames must not be empty")
    shape = np.shape(frames[0])
    if len(shape) != 3 or shape[2] != 3:
        raise ValueError(f"frames must be shaped (H, W, 3), got {shape}")
    if any(np.shape(f) != shape for f in frames):
        raise ValueError("all frames must have the same shape")
    keep = list(range(0, len(frames), int(every)))
    if keep[-1] != len(frames) - 1:
        keep.append(len(frames) - 1)
    if max_frames is not None and len(keep) > max_frames:
        pick = np.unique(np.rint(np.linspace(0, len(keep) - 1, int(max_frames))).astype(int))
        keep = [keep[i] for i in pick]
    stack = np.stack([np.asarray(frames[i]) for i in keep])
    if stack.dtype != np.uint8:
        stack = np.clip(stack, 0, 255).astype(np.uint8)

    import imageio.v3 as iio

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    iio.imwrite(path, stack, extension=".gif", duration=1000.0 / fps, loop=0)
    return path
