"""The numpy version of the corner extraction (cornerslam_cli/features/corners.py before its loops were
compiled, corner_kernels.py): the reference the compiled extraction is compared with.

The same expressions vectorised over all segment pairs and ends with numpy; kept only for the tests.
"""

from __future__ import annotations

import functools

import numpy as np

from cornerslam_cli.features.params import CornersConfig, SensorConfig
from cornerslam_cli.features.sensor import COV_FLOOR, beam_variances, sigma_range
from cornerslam_cli.geometry import wrap_angle
from cornerslam_cli.types import Corners, Scan, Segments


def intersections(segs: Segments, i: np.ndarray, j: np.ndarray):
    """Eq 9–13 for line pairs (i, j): corners (m, 3) and covariances (m, 3, 3). Pairs must not be parallel."""
    ai, aj, ri, rj = segs.alpha[i], segs.alpha[j], segs.r[i], segs.r[j]
    D = np.sin(aj - ai)  # det N
    # N⁻¹ = (1/D) [[sin αj, −sin αi], [−cos αj, cos αi]]
    ninv = np.stack(
        (np.stack((np.sin(aj), -np.sin(ai)), -1), np.stack((-np.cos(aj), np.cos(ai)), -1)), axis=1
    )
    ninv /= D[:, None, None]
    c = np.einsum("mab,mb->ma", ninv, np.column_stack((ri, rj)))
    dphi = wrap_angle(ai - aj)
    phi = np.abs(dphi)
    sgn = np.where(dphi >= 0, 1.0, -1.0)
    # N dc = dr − diag(d_i·c, d_j·c) dα,  d = (−sin α, cos α)
    dic = -np.sin(ai) * c[:, 0] + np.cos(ai) * c[:, 1]
    djc = -np.sin(aj) * c[:, 0] + np.cos(aj) * c[:, 1]
    F = np.zeros((len(i), 3, 4))
    F[:, :2, 0] = ninv[:, :, 0]
    F[:, :2, 1] = -dic[:, None] * ninv[:, :, 0]
    F[:, :2, 2] = ninv[:, :, 1]
    F[:, :2, 3] = -djc[:, None] * ninv[:, :, 1]
    F[:, 2, 1], F[:, 2, 3] = sgn, -sgn
    C = np.zeros((len(i), 4, 4))
    C[:, :2, :2], C[:, 2:, 2:] = segs.cov[i], segs.cov[j]
    z = np.column_stack((c, phi))
    return z, F @ C @ F.transpose(0, 2, 1)


def _point_segment_distance(p, a, b):
    ab = b - a
    L2 = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
    return np.hypot(*(a + t[:, None] * ab - p).T)


@functools.lru_cache(maxsize=64)
def _pairs(k: int) -> tuple[np.ndarray, np.ndarray]:
    """All index pairs i < j of k segments (np.triu_indices, cached: it is the same for every scan)."""
    i, j = np.triu_indices(k, 1)
    i.flags.writeable = j.flags.writeable = False
    return i, j


def type_one(segs: Segments, cfg: CornersConfig):
    """Type I corners from all admissible segment pairs: (z, cov, segs (m, 2))."""
    i, j = _pairs(len(segs))
    ends = np.stack((segs.p1, segs.p2), axis=1)  # (k, 2 ends, 2)
    d_end = np.hypot(*(ends[i][:, :, None, :] - ends[j][:, None, :, :]).transpose(3, 0, 1, 2)).min(
        axis=(1, 2)
    )
    phi = np.abs(wrap_angle(segs.alpha[i] - segs.alpha[j]))
    ok = (d_end < cfg.d_min) & (phi >= cfg.min_angle) & (phi <= np.pi - cfg.min_angle)
    i, j = i[ok], j[ok]
    z, cov = intersections(segs, i, j)
    near = (_point_segment_distance(z[:, :2], segs.p1[i], segs.p2[i]) <= cfg.dp_max) & (
        _point_segment_distance(z[:, :2], segs.p1[j], segs.p2[j]) <= cfg.dp_max
    )
    return z[near], cov[near], np.column_stack((i, j))[near]


def type_two(scan: Scan, segs: Segments, jac_ends: np.ndarray, sensor: SensorConfig, cfg: CornersConfig):
    """Type II corners at segment ends facing a depth jump: (z, cov, segs (m, 2) with −1 second)."""
    rho, theta = scan.ranges, scan.angles
    n, k = len(rho), len(segs)
    none = np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 2), dtype=np.int64)
    # both ends of every segment at once: end 0 = first beam (next beam before it), 1 = last (after it)
    seg_of = np.concatenate((np.arange(k), np.arange(k)))
    end_of = np.repeat([0, 1], k)
    beam = np.concatenate((segs.first, segs.last))
    step = np.where(end_of == 0, -1, 1)
    nb = beam + step  # the next beam away from the segment
    nbc = np.clip(nb, 0, n - 1)
    x, y = rho * np.cos(theta), rho * np.sin(theta)
    alpha, r_all = segs.alpha[seg_of], segs.r[seg_of]
    jump = np.hypot(x[nbc] - x[beam], y[nbc] - y[beam])
    off_line = np.abs(x[nbc] * np.cos(alpha) + y[nbc] * np.sin(alpha) - r_all)
    adjacent = (nb >= 0) & (nb < n) & (np.abs(scan.beam_index[nbc] - scan.beam_index[beam]) == 1)
    is_corner = adjacent & (jump > cfg.d_min) & (off_line > cfg.d_min)
    if cfg.drop_occluded:
        is_corner &= ~(rho[nbc] < rho[beam])
    i = np.flatnonzero(is_corner)
    if i.size == 0:
        return none
    s, b, a, r = seg_of[i], beam[i], alpha[i], r_all[i]
    ca, sa = np.cos(a), np.sin(a)
    nvec = np.column_stack((ca, sa))
    dvec = np.column_stack((-sa, ca))
    q = np.column_stack((x[b], y[b]))
    e = q[:, 0] * ca + q[:, 1] * sa - r
    c = q - e[:, None] * nvec
    # A = ∂c/∂(r, α): ∂c/∂r = n, ∂c/∂α = −(d·q) n − e d
    dq = q[:, 1] * ca - q[:, 0] * sa
    A = np.stack((nvec, -dq[:, None] * nvec - e[:, None] * dvec), axis=2)  # (m, 2, 2)
    Q = np.stack(
        (np.column_stack((np.cos(theta[b]), np.sin(theta[b]))), rho[b][:, None] * dvec_of(theta[b])), axis=2
    )
    P = dvec[:, :, None] * dvec[:, None, :]  # I − n nᵀ = d dᵀ
    AJ = A @ jac_ends[s, end_of[i]]
    var_r, var_t = beam_variances(rho[b], sensor)
    Ce = np.zeros((len(i), 2, 2))
    Ce[:, 0, 0], Ce[:, 1, 1] = var_r, var_t
    Ge = AJ + P @ Q
    Cxy = A @ segs.cov[s] @ A.transpose(0, 2, 1) - AJ @ Ce @ AJ.transpose(0, 2, 1)
    Cxy = Cxy + Ge @ Ce @ Ge.transpose(0, 2, 1)
    # the edge lies somewhere between the end beam and the next beam's bearing, where the line would be
    # hit next: centre of that gap, variance gap²/12 along the line (uniform)
    th_next = theta[b] + step[i] * _spacing(scan)
    cos_next = np.cos(th_next - a)
    t_next = r / np.where(cos_next > 1e-6, cos_next, np.nan)
    gap_vec = t_next[:, None] * np.column_stack((np.cos(th_next), np.sin(th_next))) - c
    gap = np.hypot(gap_vec[:, 0], gap_vec[:, 1])
    good = gap <= cfg.endpoint_max_gap
    c = c + 0.5 * np.where(good[:, None], gap_vec, 0.0)
    Cxy = Cxy + (np.where(good, gap, 0.0) ** 2 / 12.0)[:, None, None] * P
    cov = np.zeros((len(i), 3, 3))
    cov[:, :2, :2] = Cxy
    cov[:, 2, 2] = cfg.endpoint_phi_sigma**2
    z = np.column_stack((c, np.full(len(i), cfg.endpoint_phi)))
    return z[good], cov[good], np.column_stack((s, np.full(len(i), -1)))[good]


def dvec_of(theta):
    """(m, 2) unit vectors (−sin θ, cos θ): ∂/∂θ of (cos θ, sin θ)."""
    return np.column_stack((-np.sin(theta), np.cos(theta)))


def measured_range(
    scan: Scan, bearing: np.ndarray, dropped: float = np.nan, farther: bool = False
) -> np.ndarray:
    """Range the scan measured at each bearing: the nearer (``farther``: the farther) of the at most two
    valid beams within one beam spacing of it; ``dropped`` inside a gap of dropped beams (no return, or an
    invalid reading), nan outside the field of view."""
    m, n = len(bearing), len(scan.ranges)
    if n < 2:
        return np.full(m, np.nan)
    spacing = _spacing(scan)
    k = np.searchsorted(scan.angles, bearing)
    pick, none = (np.fmax, -np.inf) if farther else (np.fmin, np.inf)
    measured = np.full(m, none)
    for nb in (k - 1, k):
        nbc = np.clip(nb, 0, n - 1)
        near = (nb >= 0) & (nb < n) & (np.abs(scan.angles[nbc] - bearing) <= spacing)
        measured = np.where(near, pick(measured, scan.ranges[nbc]), measured)
    in_fov = (bearing >= scan.angles[0]) & (bearing <= scan.angles[-1])
    return np.where(np.isfinite(measured), measured, np.where(in_fov, dropped, np.nan))


def _spacing(scan: Scan) -> float:
    if scan.angle_increment > 0:
        return float(scan.angle_increment)
    return float(np.median(np.diff(scan.angles))) if len(scan.angles) > 1 else 0.0


def _margin(rho, sensor: SensorConfig, margin: float):
    """Tolerance of a range comparison: ``occlusion_margin`` + 3σρ at that range."""
    return margin + 3.0 * sigma_range(np.where(np.isfinite(rho), rho, 0.0), sensor)


def hidden(scan: Scan, z: np.ndarray, sensor: SensorConfig, margin: float) -> np.ndarray:
    """(m,) bool: the corner lies behind the ranges measured at its bearing, by more than the margin.

    Both beams bracketing the bearing must be in front: next to a corner a steep wall legitimately
    comes nearer by several centimetres per beam."""
    measured = measured_range(scan, np.arctan2(z[:, 1], z[:, 0]), farther=True)
    return measured < np.hypot(z[:, 0], z[:, 1]) - _margin(measured, sensor, margin)


def seen_through(
    scan: Scan, segs: Segments, z: np.ndarray, which: np.ndarray, sensor: SensorConfig, margin: float
) -> np.ndarray:
    """(m,) bool for type I corners: a segment's extension from its nearer end to the intersection crosses
    space the scan saw through (a beam there measured more than ``margin`` beyond the extended line).

    This rejects "virtual" intersections, e.g. a box face extended to a wall 15 cm behind it; at a real
    corner the beams between a segment's end and the corner hit that same wall. Dropped beams there count
    as seen through (no return).
    """
    m = len(z)
    c = z[:, :2]
    s = which.T.ravel()  # (2m,) both segments of every corner
    ends = np.stack((segs.p1[s], segs.p2[s]), axis=1)
    cc = np.tile(c, (2, 1))
    d_end = np.hypot(*(ends - cc[:, None, :]).transpose(2, 0, 1))
    e = ends[np.arange(2 * m), np.argmin(d_end, axis=1)]  # the nearer end of each segment
    f = np.array([0.25, 0.5, 0.75])[:, None, None]
    q = (e + f * (cc - e)).reshape(-1, 2)  # (3·2m, 2) samples along the extensions
    measured = measured_range(scan, np.arctan2(q[:, 1], q[:, 0]), dropped=np.inf)
    rq = np.hypot(q[:, 0], q[:, 1])
    beyond = (measured > rq + _margin(rq, sensor, margin)).reshape(6, m)
    return beyond.any(axis=0)


def merge_duplicates(z, cov, kind, radius: float) -> np.ndarray:
    """Indices of the corners kept: within ``radius`` of each other only the first in the order
    (type I before type II, then smaller trace of the position covariance) is kept."""
    order = np.lexsort((cov[:, 0, 0] + cov[:, 1, 1], kind))
    xy = z[order, :2]
    close = (np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1)) < radius).tolist()
    kept: list[int] = []
    for a in range(len(order)):
        if not any(close[a][b] for b in kept):
            kept.append(a)
    return order[kept].astype(np.int64)


def extract_corners(
    scan: Scan, segs: Segments, jac_ends: np.ndarray, sensor: SensorConfig, cfg: CornersConfig
) -> Corners:
    """Algorithm 2 on the segments of one scan (``jac_ends`` from ``lines.extract_segments``)."""
    if len(segs) == 0:
        return Corners.empty()
    z1, c1, s1 = type_one(segs, cfg)
    parts = [(z1, c1, s1, np.full(len(z1), 1, dtype=np.int8))]
    if cfg.endpoints:
        z2, c2, s2 = type_two(scan, segs, jac_ends, sensor, cfg)
        parts.append((z2, c2, s2, np.full(len(z2), 2, dtype=np.int8)))
    z = np.concatenate([p[0] for p in parts])
    cov = np.concatenate([p[1] for p in parts])
    which = np.concatenate([p[2] for p in parts]).astype(np.int64)
    kind = np.concatenate([p[3] for p in parts])
    if len(z) == 0:
        return Corners.empty()
    cov = 0.5 * (cov + cov.transpose(0, 2, 1)) + COV_FLOOR * np.eye(3)
    ok = np.isfinite(z).all(1) & np.isfinite(cov).all(axis=(1, 2))
    ok &= np.linalg.eigvalsh(np.where(ok[:, None, None], cov, np.eye(3))).min(axis=1) > 0
    z = np.where(ok[:, None], z, 0.0)
    if cfg.drop_occluded:
        ok &= ~hidden(scan, z, sensor, cfg.occlusion_margin)
    if cfg.free_space_check:
        t1 = np.flatnonzero(ok & (kind == 1))  # the check is for intersections only
        if len(t1):
            ok[t1] &= ~seen_through(scan, segs, z[t1], which[t1], sensor, cfg.occlusion_margin)
    z, cov, which, kind = z[ok], cov[ok], which[ok], kind[ok]
    if len(z) == 0:
        return Corners.empty()
    keep = merge_duplicates(z, cov, kind, cfg.duplicate_radius)
    keep = keep[np.argsort(np.arctan2(z[keep, 1], z[keep, 0]), kind="stable")]
    return Corners(z=z[keep], cov=cov[keep], kind=kind[keep], segs=which[keep])
