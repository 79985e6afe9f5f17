"""Fuzz (hypothesis, bounded) where tests/test_logs_fuzz.py and the features' property tests stop:
CARMEN text mutations, ROS 2 bag directories, raw LaserScan fields through the reader's make_scan
into the extractor, and the associators on random and near-singular covariances.

Only documented errors may escape: LogError from readers; nothing from the extractor or the
associators (an ill-conditioned innovation covariance makes a pair incompatible, never an exception).
"""

from __future__ import annotations

import math
import shutil
import tempfile
from pathlib import Path

import numpy as np
from _association_helpers import observe
from _log_fixtures import make_odoms, make_scans, write_log
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_logs_fuzz import read_everything

from cornerslam_cli.association import ASSOCIATORS, AssociationConfig
from cornerslam_cli.config import Config
from cornerslam_cli.features import extract
from cornerslam_cli.logs.base import ReadStats, make_scan
from cornerslam_cli.types import Prediction

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=list(HealthCheck))
_TMP = Path(tempfile.mkdtemp(prefix="cornerslam-fuzz2-"))
_CARMEN = write_log("carmen", _TMP, make_scans(5, beams=61), make_odoms(5)).read_text().splitlines()
_BAG2 = write_log("rosbag2-sqlite3", _TMP, make_scans(4, beams=31), make_odoms(4))

TOKENS = ["nan", "inf", "-inf", "-1", "0", "1e308", "1e-320", "x", "", "181", "-5", "ODOM", "FLASER", "#"]


# ---------------------------------------------------------------------------- CARMEN text
@FUZZ
@given(data=st.data())
def test_mutated_carmen_lines(data):
    lines = list(_CARMEN)
    for _ in range(data.draw(st.integers(1, 6))):
        i = data.draw(st.integers(0, len(lines) - 1))
        tok = lines[i].split(" ")
        op = data.draw(st.sampled_from(["token", "drop_token", "dup_line", "drop_line", "swap", "cut"]))
        if op == "token":
            tok[data.draw(st.integers(0, len(tok) - 1))] = data.draw(st.sampled_from(TOKENS))
            lines[i] = " ".join(tok)
        elif op == "drop_token" and len(tok) > 1:
            del tok[data.draw(st.integers(0, len(tok) - 1))]
            lines[i] = " ".join(tok)
        elif op == "dup_line":
            lines.insert(i, lines[i])
        elif op == "drop_line" and len(lines) > 1:
            del lines[i]
        elif op == "swap":
            j = data.draw(st.integers(0, len(lines) - 1))
            lines[i], lines[j] = lines[j], lines[i]
        else:
            lines[i] = lines[i][: data.draw(st.integers(0, len(lines[i])))]
    p = _TMP / "mutated.clf"
    p.write_text("\n".join(lines) + "\n")
    read_everything(p)


# ---------------------------------------------------------------------------- ROS 2 bag directories
@FUZZ
@given(data=st.data())
def test_mutated_rosbag2_directory(data):
    d = _TMP / "bag2_mut"
    shutil.rmtree(d, ignore_errors=True)
    shutil.copytree(_BAG2, d)
    target = data.draw(st.sampled_from(["metadata", "db3", "delete_db3"]))
    if target == "delete_db3":
        for f in d.glob("*.db3"):
            f.unlink()
    else:
        f = d / "metadata.yaml" if target == "metadata" else next(d.glob("*.db3"))
        buf = bytearray(f.read_bytes())
        if data.draw(st.booleans()):
            buf = buf[: data.draw(st.integers(0, len(buf)))]
        else:
            for _ in range(data.draw(st.integers(1, 8))):
                buf[data.draw(st.integers(0, len(buf) - 1))] = data.draw(st.integers(0, 255))
        f.write_bytes(bytes(buf))
    read_everything(d)


# ---------------------------------------------------------------------------- raw scan fields → extractor
f32 = st.floats(width=32, allow_nan=True, allow_infinity=True)


@FUZZ
@given(
    ranges=st.lists(f32, min_size=0, max_size=200),
    angle_min=f32,
    inc=f32 | st.sampled_from([1e308, 5e-324, -0.0]),
    range_min=f32,
    range_max=f32,
)
def test_raw_laserscan_fields_through_reader_and_extractor(ranges, angle_min, inc, range_min, range_max):
    """Whatever a LaserScan message holds, make_scan keeps only valid beams and extraction is finite."""
    stats = ReadStats()
    scan = make_scan(stats, "fuzz", 1.0, angle_min, None, inc, range_min, range_max, np.array(ranges))
    if scan is None:
        assert stats.scans_skipped == 1
        return
    assert np.isfinite(scan.ranges).all() and np.isfinite(scan.angles).all() and (scan.ranges > 0).all()
    cfg = Config()
    segs, corners = extract(scan, cfg.sensor, cfg.lines, cfg.corners)
    for a in (segs.r, segs.alpha, segs.cov, corners.z, corners.cov):
        assert np.isfinite(a).all()


# ---------------------------------------------------------------------------- associators
def _spd(rng: np.random.Generator, d: int, kind: str) -> np.ndarray:
    """A d×d covariance: well-conditioned, near-singular, rank-deficient, tiny or huge."""
    A = rng.normal(size=(d, d))
    if kind == "near_singular":
        w = np.geomspace(1.0, 1e-14, d)
    elif kind == "rank_deficient":
        w = np.r_[np.ones(d - 1), 0.0]
    elif kind == "tiny":
        w = np.full(d, 1e-300)
    elif kind == "huge":
        w = np.full(d, 1e150)
    else:
        w = rng.uniform(0.01, 1.0, d)
    Q, _ = np.linalg.qr(A)
    M = (Q * w) @ Q.T
    return 0.5 * (M + M.T)


KINDS = ["ok", "near_singular", "rank_deficient", "tiny", "huge"]


@FUZZ
@given(
    name=st.sampled_from(sorted(ASSOCIATORS)),
    m=st.integers(0, 7),
    n=st.integers(0, 7),
    p_kind=st.sampled_from(KINDS),
    c_kind=st.sampled_from(KINDS),
    seed=st.integers(0, 2**31),
    use_phi=st.booleans(),
)
def test_associators_on_random_and_near_singular_covariances(name, m, n, p_kind, c_kind, seed, use_phi):
    rng = np.random.default_rng(seed)
    pose = rng.uniform([-5, -5, -math.pi], [5, 5, math.pi])
    lm = np.column_stack((rng.uniform(-8, 8, (n, 2)), rng.uniform(0, math.pi, n)))
    h, H_r, H_l = observe(pose, lm)
    P = _spd(rng, 3 + 3 * n, p_kind)
    pred = Prediction(h=h, H_r=H_r, H_l=H_l, P=P)
    # corners: some near landmarks (so pairs are tried), the rest anywhere
    z = np.column_stack((rng.uniform(-8, 8, (m, 2)), rng.uniform(0, math.pi, m)))
    k = min(m, n)
    z[:k] = h[:k] + rng.normal(0, 0.05, (k, 3))
    C = np.stack([_spd(rng, 3, c_kind) for _ in range(m)]) if m else np.zeros((0, 3, 3))
    assoc = ASSOCIATORS[name](AssociationConfig(method=name, use_phi=use_phi))
    res = assoc(z, C, pred)
    pairs = np.asarray(res.pairs)
    assert pairs.shape == (m,) and ((pairs >= -1) & (pairs < n)).all()
    matched = pairs[pairs >= 0]
    if name != "icnn":  # ICNN lets two corners take one landmark, as in the paper
        assert len(np.unique(matched)) == len(matched)
    assert np.isfinite(np.asarray(res.d2)[pairs >= 0]).all()
