"""Are the extractor's line and corner covariances honest? Monte Carlo against known scenes, and the
normalised innovations of the filter's matched pairs on a real log.

    python benchmarks/corner_covariance_mc.py lines   [--draws 800]
    python benchmarks/corner_covariance_mc.py corners [--draws 200]
    python benchmarks/corner_covariance_mc.py innovations LOG [--config FILE]

A diagnostic (nothing here changes the library); findings: docs/results/review_features_filter.md.

* ``lines``: ``lines.fit_ranges`` on the beams of one wall at perpendicular distance R, seen at incidence
  ``inc`` (beam against the wall's normal) over L metres, URG-04LX beam spacing (0.352°), the URG-04LX
  preset's noise and the default (paper) model. Per case: beams, Var(e)/σ² and E[e²]/σ² of r and α
  (σ² the mean predicted variance), and the mean error in σ.
* ``corners``: type I corners through ``features.extract`` (URG-04LX preset, 682 beams over 240°) against
  the same corner from ``fit_ranges`` on each wall's own beams (the segmentation taken out) and
  ``corner_kernels.intersection``; type II corners (a wall's free end, anywhere in the gap between two
  beams, in front of a wall 1.5 m behind). E[e²]/σ² per component (x, y, φ; for type II along and across
  the wall), the mean error in σ, the predicted σ and the RMS error.
* ``innovations``: the run of ``cornerslam run`` (in process, its files discarded) with every matched
  pair's innovation ν and S = H Σ Hᵀ + C recorded before its update: mean ν²/S per component for type I
  and type II pairs (type II: C's σφ is ``corners.endpoint_phi_sigma``). After the χ²₃ gate an honest S
  gives a mean ν²/S of ~0.8 per component (D² ≤ 2.43).
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from cornerslam_cli import simworld as sw
from cornerslam_cli.features import CornersConfig, LinesConfig, SensorConfig, extract, sigma_range
from cornerslam_cli.features.corner_kernels import intersection
from cornerslam_cli.features.lines import fit_ranges

URG = SensorConfig(model="piecewise", sigma_r_near=0.01, near_range=1.0, sigma_r_rel=0.01)
STEP = math.radians(240.0 / 681)
ANGLES = (np.arange(682) - 340.5) * STEP


def noisy(r, alpha, bearings, sensor, rng):
    """Ranges to the line (r, α) along ``bearings`` + N(0, σθ²), plus N(0, σρ²) (eq 1)."""
    rho = r / np.cos(bearings + rng.normal(0.0, sensor.sigma_theta, bearings.shape) - alpha)
    return rho + rng.normal(0.0, 1.0, rho.shape) * sigma_range(rho, sensor)


def grid(a0, a1):
    return np.arange(math.ceil(a0 / STEP), math.floor(a1 / STEP) + 1) * STEP


def ratios(err, cov):
    """(Var(e)/σ², E[e²]/σ², mean e/σ) per component."""
    pred = np.diag(cov.mean(0))
    return np.var(err, 0) / pred, np.mean(err**2, 0) / pred, err.mean(0) / np.sqrt(pred)


def lines(draws: int) -> None:
    print("| sensor | R m | inc ° | L m | beams | Var/σ² r, α | E[e²]/σ² r, α | bias/σ r, α |")
    print("|---|---:|---:|---:|---:|---|---|---|")
    for name, sensor in (("URG-04LX", URG), ("default", SensorConfig())):
        for R in (1.0, 2.0, 4.0):
            for inc in (0, 45, 70):
                for L in (0.3, 1.0, 3.0):
                    c = R * math.tan(math.radians(inc))
                    th = grid(math.atan2(c - L / 2, R), math.atan2(c + L / 2, R))
                    if len(th) < LinesConfig().min_points:
                        continue
                    rng = np.random.default_rng(0)
                    err, cov = np.zeros((draws, 2)), np.zeros((draws, 2, 2))
                    for k in range(draws):
                        f = fit_ranges(noisy(R, 0.0, th, sensor, rng), th, sensor, [0], [len(th)])
                        err[k], cov[k] = (f.r[0] - R, math.remainder(f.alpha[0], 2 * math.pi)), f.cov[0]
                    v, m, b = ratios(err, cov)
                    print(f"| {name} | {R:.0f} | {inc} | {L} | {len(th)} | {v[0]:.2f}, {v[1]:.2f} | "
                          f"{m[0]:.2f}, {m[1]:.2f} | {b[0]:+.2f}, {b[1]:+.2f} |")  # fmt: skip


def _rot(v, a):
    c, s = math.cos(a), math.sin(a)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def _normal_angle(p, q):
    d = np.subtract(q, p)
    n = np.array([-d[1], d[0]]) / math.hypot(*d)
    return math.atan2(*(n if n @ p >= 0 else -n)[::-1])


def _scan(world, sensor, rng):
    return sw.simulate_scan(world, (0.0, 0.0, 0.0), ANGLES, 5.6, lambda r: sigma_range(r, sensor),
                            sensor.sigma_theta, rng)  # fmt: skip


def _row(name, found, draws, err, cov, labels=("x", "y", "φ")):
    v, m, b = ratios(err, cov)
    sd, rms = np.sqrt(np.diag(cov.mean(0))), np.sqrt(np.mean(err**2, 0))
    unit = np.array([1000.0] * 2 + [math.degrees(1.0)] * (len(labels) - 2))
    cells = [f"{found}/{draws}", _join(m, ".2f"), _join(v, ".2f"), _join(b, "+.2f"), _join(sd * unit, ".1f")]
    print(f"| {name} | " + " | ".join(cells + [_join(rms * unit, ".1f")]) + " |")


def _join(values, spec):
    return ", ".join(format(float(x), spec) for x in values)


def corners(draws: int) -> None:
    print("type I (x, y, φ; mm, mm, °). 'true beams': each wall's own beams fitted, then eq 9–13.\n")
    print("| corner | found | E[e²]/σ² | Var/σ² | bias/σ | σ predicted | RMS error |")
    print("|---|---|---|---|---|---|---|")
    for D in (1.0, 2.0, 3.5):
        for wedge, turn, arms in (
            (90, 0, (1.5, 1.5)),
            (90, 30, (1.5, 1.5)),
            (90, 0, (0.4, 1.5)),
            (120, 0, (1.5, 1.5)),
        ):
            corner = D * np.array([math.cos(0.3), math.sin(0.3)])
            back = -corner / D  # a room corner: its walls come back towards the sensor
            h, t = math.radians(wedge) / 2, math.radians(turn)
            ends = [corner + arms[0] * _rot(back, h + t), corner + arms[1] * _rot(back, -h + t)]
            truth = np.array([*corner, abs(math.remainder(
                _normal_angle(corner, ends[0]) - _normal_angle(corner, ends[1]), 2 * math.pi))])  # fmt: skip
            world = sw.make_world([sw.polyline([ends[0], corner, ends[1]])])
            name = f"{D} m, {wedge}°, turned {turn}°, arms {arms[0]}/{arms[1]} m"
            for label, true_beams in (("extractor", False), ("true beams", True)):
                rng = np.random.default_rng(1)
                err, cov = [], []
                for _ in range(draws):
                    z, c = (
                        _true_beams(corner, ends, URG, rng)
                        if true_beams
                        else _extracted(world, truth, 1, rng)
                    )
                    if z is not None:
                        err.append(z - truth)
                        cov.append(c)
                if len(err) >= 20:
                    _row(f"{name}: {label}", len(err), draws, np.array(err), np.array(cov))
    print("\ntype II (along, across the wall; mm)\n")
    print("| end | found | E[e²]/σ² | Var/σ² | bias/σ | σ predicted | RMS error |")
    print("|---|---|---|---|---|---|---|")
    for D in (1.0, 2.0, 3.5):
        for inc in (0, 30, 60):
            rng = np.random.default_rng(3)
            err, cov = [], []
            for _ in range(draws):
                b = 0.2 + rng.uniform(0.05, 0.95) * STEP  # the end anywhere between two beams
                u = np.array([math.cos(b), math.sin(b)])
                along = _rot(u, -math.pi / 2 + math.radians(inc))
                world = sw.make_world([sw.polyline([D * u, D * u + 1.5 * along]),
                                       sw.polyline([(D + 1.5, -8.0), (D + 1.5, 8.0)])])  # fmt: skip
                z, c = _extracted(world, np.array([*(D * u), math.pi / 2]), 2, rng)
                if z is not None:
                    R = np.array([along, [-along[1], along[0]]])
                    err.append(R @ (z[:2] - D * u))
                    cov.append(R @ c[:2, :2] @ R.T)
            if len(err) >= 20:
                _row(
                    f"{D} m, incidence {inc}°",
                    len(err),
                    draws,
                    np.array(err),
                    np.array(cov),
                    ("along", "across"),
                )


def _extracted(world, truth, kind, rng):
    _, cs = extract(_scan(world, URG, rng), URG, LinesConfig(), CornersConfig())
    if len(cs.z) == 0:
        return None, None
    d = np.hypot(*(cs.z[:, :2] - truth[:2]).T)
    i = int(np.argmin(d))
    if d[i] > 0.15 or cs.kind[i] != kind:
        return None, None
    return cs.z[i], cs.cov[i]


def _true_beams(corner, ends, sensor, rng):
    fits = []
    b_corner = math.atan2(corner[1], corner[0])
    for end in ends:
        alpha = _normal_angle(corner, end)
        r = float(np.array([math.cos(alpha), math.sin(alpha)]) @ corner)
        b_end = math.atan2(end[1], end[0])
        th = grid(min(b_corner, b_end), max(b_corner, b_end))
        th = th[(th != b_corner)]
        fits.append(fit_ranges(noisy(r, alpha, th, sensor, rng), th, sensor, [0], [len(th)]))
    f1, f2 = fits
    return intersection(f1.alpha[0], f2.alpha[0], f1.r[0], f2.r[0], f1.cov[0], f2.cov[0])


def innovations(log: str, config: str | None) -> None:
    import cornerslam_cli.frontend as fe
    from cornerslam_cli.filter.ekf import Ekf
    from cornerslam_cli.filter.models import observe_one
    from cornerslam_cli.lasers import resolve_config
    from cornerslam_cli.pipeline import run_filter
    from cornerslam_cli.report.run_writer import load_reference

    records = []
    update = Ekf.update

    def recorded(self, ids, z, C):
        for k, z_i, C_i in zip(
            np.ravel(ids).tolist(), np.reshape(z, (-1, 3)), np.reshape(C, (-1, 3, 3)), strict=True
        ):
            h, H = observe_one(self.mu[:3], self.mu[3 + 3 * k : 6 + 3 * k])
            cols = [0, 1, 2, 3 + 3 * k, 4 + 3 * k, 5 + 3 * k]
            nu = z_i - h
            nu[2] = math.remainder(nu[2], 2 * math.pi)
            records.append((nu, H @ self.P[np.ix_(cols, cols)] @ H.T + C_i, C_i))
        return update(self, ids, z, C)

    Ekf.update = recorded
    cfg = resolve_config(log, config)
    src = fe.open_input(log, cfg)
    with tempfile.TemporaryDirectory() as tmp:
        run_filter(fe.frames(src, cfg), src, cfg, Path(tmp), load_reference(Path(log)), time.perf_counter())
    Ekf.update = update
    nu, S, C = (np.array([r[i] for r in records]) for i in range(3))
    kind2 = np.abs(np.sqrt(C[:, 2, 2]) - cfg.corners.endpoint_phi_sigma) < 1e-3
    print(f"{log}: {len(nu)} matched pairs")
    print("| pairs | n | mean D² | ν²/S x, y, φ | median σ of S x; φ | RMS ν xy; φ | median σφ of C |")
    print("|---|---:|---:|---|---|---|---|")
    for name, sel in (("type I", ~kind2), ("type II", kind2)):
        if sel.sum() == 0:
            continue
        n, s = nu[sel], S[sel]
        d2 = np.einsum("ni,ni->n", n, np.linalg.solve(s, n[..., None])[..., 0])
        z2 = n**2 / np.diagonal(s, axis1=1, axis2=2)
        sd_xy, sd_phi = 100 * np.median(np.sqrt(s[:, 0, 0])), math.degrees(np.median(np.sqrt(s[:, 2, 2])))
        rms_xy, rms_phi = 100 * np.sqrt(np.mean(n[:, :2] ** 2)), math.degrees(np.sqrt(np.mean(n[:, 2] ** 2)))
        c_phi = math.degrees(np.median(np.sqrt(C[sel, 2, 2])))
        cells = [str(sel.sum()), f"{d2.mean():.2f}", _join(z2.mean(0), ".2f")]
        cells += [f"{sd_xy:.1f} cm; {sd_phi:.2f}°", f"{rms_xy:.1f} cm; {rms_phi:.2f}°", f"{c_phi:.2f}°"]
        print(f"| {name} | " + " | ".join(cells) + " |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("lines", "corners", "innovations"))
    ap.add_argument("log", nargs="?")
    ap.add_argument("--config")
    ap.add_argument("--draws", type=int, default=0)
    a = ap.parse_args(argv)
    with np.errstate(all="ignore"):
        if a.what == "lines":
            lines(a.draws or 800)
        elif a.what == "corners":
            corners(a.draws or 200)
        else:
            if not a.log:
                ap.error("innovations needs a LOG")
            innovations(a.log, a.config)
    return 0


if __name__ == "__main__":
    sys.exit(main())
