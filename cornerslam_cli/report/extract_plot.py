"""Terminal table and figure of one scan's features (``cornerslam extract``; paper Figs 14–15)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..types import Corners, Scan, Segments
from .ownership import figure_mark

KIND_NAMES = {1: "I  intersection", 2: "II end point"}


def format_extraction(segments: Segments, corners: Corners) -> str:
    """A readable table of the segments (r, α, σ, end points) and corners (x, y, φ, σ) of one scan."""
    lines = [f"{_counted(len(segments), 'segment')} (sensor frame; σ from the covariance)"]
    lines.append(
        f"{'#':>3} {'r [m]':>8} {'α [deg]':>9} {'σr [mm]':>8} {'σα [deg]':>9} {'n':>5} {'length':>7}"
        "   p1 → p2 [m]"
    )
    for k in range(len(segments)):
        p1, p2 = segments.p1[k], segments.p2[k]
        lines.append(
            f"{k:>3} {segments.r[k]:8.3f} {math.degrees(segments.alpha[k]):9.2f} "
            f"{1e3 * math.sqrt(segments.cov[k, 0, 0]):8.1f} "
            f"{math.degrees(math.sqrt(segments.cov[k, 1, 1])):9.3f} "
            f"{segments.n_points[k]:>5} {np.hypot(*(p2 - p1)):7.2f}   "
            f"({p1[0]:6.2f}, {p1[1]:6.2f}) → ({p2[0]:6.2f}, {p2[1]:6.2f})"
        )
    lines.append("")
    lines.append(_counted(len(corners), "corner"))
    lines.append(
        f"{'#':>3} {'type':<16} {'x [m]':>8} {'y [m]':>8} {'φ [deg]':>8} {'σx [mm]':>8} {'σy [mm]':>8} "
        f"{'σφ [deg]':>9}  segments"
    )
    for k in range(len(corners)):
        x, y, phi = corners.z[k]
        sd = np.sqrt(np.diag(corners.cov[k]))
        segs = ", ".join(str(int(s)) for s in corners.segs[k] if s >= 0)
        lines.append(
            f"{k:>3} {KIND_NAMES.get(int(corners.kind[k]), '?'):<16} {x:8.3f} {y:8.3f} "
            f"{math.degrees(phi):8.2f} "
            f"{1e3 * sd[0]:8.1f} {1e3 * sd[1]:8.1f} {math.degrees(sd[2]):9.3f}  {segs}"
        )
    return "\n".join(lines)


def _ellipse(mean: np.ndarray, cov: np.ndarray, n_sigma: float = 3.0, n: int = 60) -> np.ndarray:
    """(n, 2) points of the n_sigma ellipse of a 2D Gaussian."""
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    t = np.linspace(0.0, 2.0 * np.pi, n)
    circle = np.stack((np.cos(t), np.sin(t)))
    return (mean[:, None] + vecs @ (n_sigma * np.sqrt(np.maximum(vals, 0.0))[:, None] * circle)).T


def plot_extraction(
    scan: Scan, segments: Segments, corners: Corners, path, title: str = "", fmt: str | None = None
) -> None:
    """Draw the scan points, segments and corners with their 3σ position ellipses to ``path`` (PNG, …;
    ``fmt``: the format, by default the one its suffix names).

    Sensor frame, metres, equal aspect. Type I corners are dots, type II (end points) stars, as in the
    paper's Fig 14; the ellipses are the (x, y) block of each corner's covariance (Fig 15).
    """
    from .plots import pyplot

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 8))
    pts = scan.points()
    ax.plot(pts[:, 0], pts[:, 1], ".", ms=2, color="0.6", label=f"scan ({len(pts)} beams)")
    ax.plot([0], [0], marker=(3, 0, -90), ms=12, color="k", ls="", label="sensor")
    for k in range(len(segments)):
        p = np.stack((segments.p1[k], segments.p2[k]))
        ax.plot(p[:, 0], p[:, 1], "-", lw=2, color="tab:blue", label="segments" if k == 0 else None)
    for kind, marker, color, name in ((1, "o", "tab:red", "corners I"), (2, "*", "tab:orange", "corners II")):
        sel = np.flatnonzero(corners.kind == kind)
        if sel.size:
            ax.plot(corners.z[sel, 0], corners.z[sel, 1], marker, ms=9, color=color, ls="", label=name)
        for i in sel:
            e = _ellipse(corners.z[i, :2], corners.cov[i, :2, :2])
            ax.plot(e[:, 0], e[:, 1], "-", lw=1, color=color)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m] (sensor frame)")
    ax.set_ylabel("y [m]")
    ax.set_title(
        title or f"{_counted(len(segments), 'segment')}, {_counted(len(corners), 'corner')} (3σ ellipses)"
    )
    ax.grid(True, lw=0.3)
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    # marked as ours where the format can say so: a later extract --plot may replace it (ownership.py)
    fmt = fmt or Path(path).suffix[1:].lower()  # (the format: of the name, unless given)
    fig.savefig(Path(path), dpi=120, format=fmt, **figure_mark(fmt))
    plt.close(fig)


def _counted(n: int, what: str) -> str:
    """``n`` and ``what``, plural unless one: "1 corner", "3 corners"."""
    return f"{n} {what}" + ("" if n == 1 else "s")
