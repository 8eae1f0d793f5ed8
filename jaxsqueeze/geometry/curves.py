"""Closed planar outlines for band objects (Section V-A): circle, heart and leaf.

Each constructor returns a *curve*: a vectorized function ``gamma(p)`` of a parameter
``p in [0, 1)`` (any shape ``(k,)``) returning points ``(k, 2)`` [m] on a closed, simple,
counterclockwise, smooth (C-infinity, regular) curve, centred on its bounding box. The
parameter is not arc length; :func:`sample` places points uniformly in arc length.
The sizes default to those of ordinary cookie cutters (about 8 cm across), the objects of
the paper's band experiments (Fig. 2).

- :func:`circle` -- radius ``radius`` (default 4 cm).
- :func:`heart` -- the classic parametric heart
  ``x = 16 sin^3 t, y = 13 cos t - 5 cos 2t - 2 cos 3t - cos 4t``, whose top dimple and
  bottom tip are singular points (zero speed, unbounded curvature). Every Fourier harmonic
  k of (x, y) is damped by ``exp(-(smoothing k)^2)``, which makes the curve regular and
  rounds both points. With the default ``smoothing=0.25`` and ``size=0.08`` (8.0 cm wide,
  7.4 cm tall) the smallest radius of curvature is about 2.5 mm (at the bottom tip) and
  3 mm at the dimple (where the curvature is negative: the outline is concave there); the
  dimple is about 12% of the height deep, the perimeter about 24.7 cm.
- :func:`leaf` -- a lens with rounded tips: ``x = a cos t``,
  ``y = b sin t sqrt(sin^2 t + e^2) / sqrt(1 + e^2)`` with half-length ``a = length/2``,
  half-width ``b = width/2`` and ``e`` chosen so that the tip radius of curvature is ``tip``.
  ``e -> 0`` is the sharp parabolic lens. Defaults: 8 cm long, 4 cm wide, tip radius 2 mm.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from ..numbers import positive, real_array

Curve = Callable[[np.ndarray], np.ndarray]


def circle(radius: float = 0.04) -> Curve:
    """Circle of ``radius`` [m] centred at the origin, counterclockwise, starting on +x."""
    r = positive(radius, "the circle radius", "m")

    def gamma(p):
        a = 2.0 * np.pi * np.asarray(p, dtype=np.float64)
        return r * np.stack([np.cos(a), np.sin(a)], axis=-1)

    return gamma


def _heart_raw(p, smoothing):
    t = -2.0 * np.pi * np.asarray(p, dtype=np.float64)     # the classic heart runs clockwise
    f = lambda k: np.exp(-(smoothing * k) ** 2)            # noqa: E731
    x = 12.0 * f(1) * np.sin(t) - 4.0 * f(3) * np.sin(3 * t)   # 16 sin^3 t
    y = 13.0 * f(1) * np.cos(t) - 5.0 * f(2) * np.cos(2 * t) - 2.0 * f(3) * np.cos(3 * t) - f(4) * np.cos(4 * t)
    return np.stack([x, y], axis=-1)


def heart(size: float = 0.08, smoothing: float = 0.25) -> Curve:
    """Smoothed heart outline, ``size`` [m] wide, dimple up, tip down, counterclockwise.

    ``smoothing`` (> 0, dimensionless) damps harmonic k by ``exp(-(smoothing k)^2)``; larger
    values give rounder (less heart-like) outlines. ``p = 0`` is the top dimple.
    """
    size, smoothing = positive(size, "the heart size", "m"), positive(smoothing, "the heart smoothing")
    if not 0.1 <= smoothing <= 0.4:
        raise ValueError(f"heart smoothing must lie in [0.1, 0.4] (bounded curvature, heart-like), got {smoothing!r}")
    dense = _heart_raw(np.arange(4096) / 4096, smoothing)
    lo, hi = dense.min(axis=0), dense.max(axis=0)
    scale, centre = size / (hi[0] - lo[0]), 0.5 * (lo + hi)

    def gamma(p):
        return (_heart_raw(p, smoothing) - centre) * scale

    return gamma


def leaf(length: float = 0.08, width: float = 0.04, tip: float = 0.002) -> Curve:
    """Leaf (lens with rounded tips) ``length`` x ``width`` [m], long axis along x.

    ``tip`` [m] is the radius of curvature at the two tips; it must be below
    ``(width/2)^2 / (length/2)`` (the radius of the ellipse with the same axes).
    Counterclockwise, ``p = 0`` at the +x tip.
    """
    a, b = 0.5 * positive(length, "the leaf length", "m"), 0.5 * positive(width, "the leaf width", "m")
    r = positive(tip, "the leaf tip radius", "m")
    q = r * a / b**2
    if q >= 1.0:
        raise ValueError(f"leaf tip radius {tip!r} m must be below (width/2)^2/(length/2) = {b * b / a:g} m")
    e = np.sqrt(q / (1.0 - q))

    def gamma(p):
        t = 2.0 * np.pi * np.asarray(p, dtype=np.float64)
        s = np.sin(t)
        return np.stack([a * np.cos(t), b * s * np.sqrt(s * s + e * e) / np.sqrt(1.0 + e * e)], axis=-1)

    return gamma


def arclength_params(curve: Curve, m: int, dense: int | None = None) -> np.ndarray:
    """Parameters ``p`` (m,) in [0, 1) of m points uniformly spaced in arc length along ``curve``.

    Arc length comes from a dense polyline (``dense`` points, default ``max(64 m, 8192)``),
    interpolated linearly; p = 0 is kept as the first point.
    """
    n = max(64 * m, 8192) if dense is None else int(dense)
    p = np.arange(n + 1) / n
    xy = real_array(curve(p), "the curve's points", "m")
    if xy.shape != (n + 1, 2) or not np.all(np.isfinite(xy)):
        what = f"shape {xy.shape}" if xy.shape != (n + 1, 2) else "points that are not finite"
        raise ValueError(f"the curve maps k parameters in [0, 1] to finite (k, 2) points [m]; for {n + 1} it "
                         f"gave {what}")
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    return np.interp(np.arange(m) / m * s[-1], s, p)


def sample(curve: Curve, m: int) -> np.ndarray:
    """Closed polyline (m, 2) [m] of ``m`` points uniformly spaced in arc length (no repeat)."""
    if m < 3:
        raise ValueError(f"a closed polyline needs m >= 3 points, got {m}")
    return curve(arclength_params(curve, m))
