"""Map consistency without ground truth (report/consistency.py): hand-made scans whose occupied cells
and revisit misalignment are known, and the figures in a simulated run's summary.json."""

from __future__ import annotations

import dataclasses
import json
import math
import tracemalloc

import numpy as np
import pytest
import scipy.spatial  # noqa: F401  (imported before tracemalloc starts: not the figures' memory)
from click.testing import CliRunner

from cornerslam_cli.cli import cli
from cornerslam_cli.report import consistency
from cornerslam_cli.report.consistency import (
    CELL,
    REVISIT_BLOCK,
    REVISIT_CAP,
    REVISIT_GAP,
    map_consistency,
    occupied_cells,
    place,
    revisit_misalignment,
)
from cornerslam_cli.report.occupancy import ScanStore
from cornerslam_cli.report.revisit_grid import nearest_far
from cornerslam_cli.results import MapConsistency


def wall_scan() -> np.ndarray:
    """20 points 1 m ahead of the laser, along a wall, one at the centre of each 5 cm cell."""
    return np.column_stack((np.full(20, 1.0 + CELL / 2), CELL * (np.arange(20) + 0.5)))


def test_place_rotates_and_translates_each_scan_by_its_pose():
    pts = [np.array([[1.0, 0.0]]), np.array([[1.0, 0.0], [0.0, 2.0]])]
    poses = np.array([[0.0, 0.0, 0.0], [1.0, -1.0, math.pi / 2]])
    np.testing.assert_allclose(place(pts, poses), [[1, 0], [1, 0], [-1, -1]], atol=1e-12)


def test_occupied_cells_count_a_wall_once_when_the_scans_agree_and_twice_when_they_do_not():
    pts = [wall_scan(), wall_scan()]
    same = np.zeros((2, 3))
    assert occupied_cells(pts, same) == 20
    shifted = np.array([[0.0, 0.0, 0.0], [2 * CELL, 0.0, 0.0]])  # the second scan's wall 10 cm further
    assert occupied_cells(pts, shifted) == 40
    along = np.array([[0.0, 0.0, 0.0], [0.0, 10 * CELL, 0.0]])  # half the wall seen again, half new
    assert occupied_cells(pts, along) == 30


def revisit_case() -> tuple[list[np.ndarray], np.ndarray]:
    """200 scans of one point each (8 blocks of 25; neighbours from blocks >= 4 away): scans 0–99
    place it at (0, 0), 100–149 10 cm away, 150–199 1 m away (beyond the cap). Blocks 0, 1 meet
    blocks 4, 5 at 0.1 m; blocks 2, 3 only reach 6, 7 (too far); 6, 7 only 2, 3."""
    pts = [np.array([[1.0, 0.0]])] * 200
    x = np.concatenate((np.zeros(100), np.full(50, 0.1), np.full(50, 1.0)))
    poses = np.column_stack((x - 1.0, np.zeros(200), np.zeros(200)))
    return pts, poses


def test_revisit_misalignment_measures_only_scans_far_apart_in_the_sequence():
    pts, poses = revisit_case()
    mean, share = revisit_misalignment(pts, poses)
    assert mean == pytest.approx(0.1) and share == 0.5
    # every scan in one place: all revisited, no misalignment
    assert revisit_misalignment(pts, np.column_stack((np.full(200, -1.0), np.zeros((200, 2))))) == (0.0, 1.0)
    # a run that never comes back: 99 scans are fewer than the gap
    mean, share = revisit_misalignment(pts[:99], poses[:99])
    assert math.isnan(mean) and share == 0


def brute_force_revisit(pts: list[np.ndarray], poses: np.ndarray) -> tuple[float, float]:
    """The revisit figures by their definition: every point against every point of the scans in
    blocks at least REVISIT_GAP // REVISIT_BLOCK away, capped, no kd-tree."""
    placed = place(pts, poses)
    block = np.repeat(np.arange(len(pts)), [len(p) for p in pts]) // REVISIT_BLOCK
    far = np.abs(block[:, None] - block[None, :]) >= REVISIT_GAP // REVISIT_BLOCK
    d = np.hypot(*(placed[:, None, :] - placed[None, :, :]).transpose(2, 0, 1))
    best = np.where(far, d, np.inf).min(axis=1, initial=np.inf)
    revisited = best[best <= REVISIT_CAP]
    return (float(revisited.mean()) if len(revisited) else math.nan), len(revisited) / max(len(placed), 1)


@pytest.mark.parametrize("seed", range(3))
def test_revisit_misalignment_equals_the_brute_force_definition(seed):
    """Scans of 0–6 points (some empty, empty ones last too), jittered about a few places, over
    23 blocks: the grid search gives the figures of the definition."""
    rng = np.random.default_rng(seed)
    n = 23 * REVISIT_BLOCK + 7
    pts = [rng.normal(0.0, 0.5, (rng.integers(0, 7), 2)) for _ in range(n)] + [np.zeros((0, 2))] * 30
    poses = np.column_stack((rng.normal(0.0, 0.2, (n + 30, 2)), rng.normal(0.0, 0.2, n + 30)))
    mean, share = revisit_misalignment(pts, poses)
    want_mean, want_share = brute_force_revisit(pts, poses)
    assert share == want_share and 0 < share < 1
    assert mean == pytest.approx(want_mean, rel=1e-12)


def brute_nearest_far(xy: np.ndarray, blocks: np.ndarray, query: np.ndarray, gap: int, cap: float):
    """nearest_far by its definition, every pair: dx² + dy² (numpy: no fused multiply-add), strictly
    below cap², the square root of the least."""
    q = np.flatnonzero(query)
    d2 = (xy[q, None, 0] - xy[None, :, 0]) ** 2 + (xy[q, None, 1] - xy[None, :, 1]) ** 2
    d2 = np.where(np.abs(blocks[q, None] - blocks[None, :]) >= gap, d2, np.inf).min(axis=1, initial=np.inf)
    return np.where(d2 < cap * cap, np.sqrt(d2), np.inf)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("grain", [0.0, 0.1, 0.05])
def test_the_grid_search_finds_the_definitions_distances_bit_for_bit(seed, grain):
    """Points over a few metres (continuous, or on a 10 cm / 5 cm lattice: exact ties and distances of
    exactly the cap), with far-flung ones beside them, blocks in scan order: every query's distance is the
    brute-force one to the last bit, inf beyond the cap alike."""
    rng = np.random.default_rng(seed)
    n = 1500
    xy = rng.uniform(-1.5, 1.5, (n, 2)) * rng.choice([0.2, 1.0, 4.0], (n, 1))
    if grain:
        xy = np.round(xy / grain) * grain
    blocks = np.sort(rng.integers(0, 12, n))
    query = rng.random(n) < 0.7
    got = nearest_far(xy, blocks, query, 4, REVISIT_CAP)
    want = brute_nearest_far(xy, blocks, query, 4, REVISIT_CAP)
    assert np.array_equal(got, want) and np.isfinite(got).sum() > 100 and np.isinf(got).sum() > 10


def test_map_consistency_compares_the_estimate_with_the_odometry():
    pts, poses = revisit_case()
    odoms = poses.copy()
    odoms[100:, 1] += 0.5  # the odometry drifted sideways: the second half's points land elsewhere
    m = map_consistency(pts, poses, odoms)
    assert (m.scans, m.points, m.cell) == (200, 200, CELL)
    assert (m.occupied_cells, m.odom_occupied_cells) == (3, 3)
    assert m.revisit_mean == pytest.approx(0.1) and m.revisit_share == 0.5
    assert math.isnan(m.odom_revisit_mean) and m.odom_revisit_share == 0
    walls = map_consistency([wall_scan()] * 2, np.zeros((2, 3)), np.array([[0, 0, 0], [0.1, 0, 0]]))
    assert (walls.occupied_cells, walls.odom_occupied_cells, walls.cells_vs_odom) == (20, 40, 0.5)


def test_a_simulated_run_reports_a_map_sharper_and_more_consistent_than_its_odometry(sim_log, tmp_path):
    out = tmp_path / "run"
    res = CliRunner().invoke(cli, ["run", str(sim_log), "--out", str(out), "-q"])
    assert res.exit_code == 0, res.output
    s = json.loads((out / "summary.json").read_text())
    c = s["consistency"]
    assert list(s)[-1] == "consistency"
    assert c["scans"] == s["counts"]["steps"] and 0 < c["points"] <= s["counts"]["beams_total"]
    assert c["cells_vs_odom"] == pytest.approx(c["occupied_cells"] / c["odom_occupied_cells"])
    assert c["cells_vs_odom"] < 0.9  # the simulated odometry drifts: its map is smeared
    assert 0 < c["revisit_mean"] < c["odom_revisit_mean"] and c["revisit_share"] > c["odom_revisit_share"]


def test_map_consistency_of_no_scans_is_empty_not_an_error():
    m = map_consistency([], np.zeros((0, 3)), np.zeros((0, 3)))
    assert (m.scans, m.points, m.occupied_cells, m.odom_occupied_cells) == (0, 0, 0, 0)
    assert math.isnan(m.cells_vs_odom) and math.isnan(m.revisit_mean) and m.revisit_share == 0


def multi_place_case(seed: int) -> tuple[list[np.ndarray], np.ndarray]:
    """Scans of 0–30 points jittered about four places 5 m apart, visited in turn (each place comes
    back every 4 × 30 scans): a map whose tiles each hold a part of the revisits."""
    rng = np.random.default_rng(seed)
    n = 16 * REVISIT_BLOCK + 9
    centre = np.array([[0.0, 0.0], [5.0, 0.0], [5.0, 5.0], [0.0, 5.0]])[(np.arange(n) // 30) % 4]
    pts = [rng.normal(0.0, 0.6, (rng.integers(0, 31), 2)) for _ in range(n)]
    poses = np.column_stack((centre + rng.normal(0.0, 0.05, (n, 2)), rng.normal(0.0, 0.05, n)))
    return pts, poses


@pytest.mark.parametrize("seed", range(2))
def test_figures_by_tiles_are_those_of_all_points_at_once(seed, monkeypatch):
    """Tiles of at most 300 points (squares of 4 cells, so points near a tile's edge find their
    neighbours in its margin): the occupied cells and revisit share of one tile exactly, the mean to
    the last bits, both equal to the brute-force definition."""
    pts, poses = multi_place_case(seed)
    whole = consistency.figures(pts, poses)
    assert len(consistency.tiles(pts, poses)) == 1
    monkeypatch.setattr(consistency, "TILE_POINTS", 300)
    monkeypatch.setattr(consistency, "BIN", 4)
    cut = consistency.tiles(pts, poses)
    assert len(cut) > 10
    tiled = consistency.figures(pts, poses)
    assert tiled[:2] == whole[:2] and tiled[3] == whole[3] and 0 < whole[3] < 1
    assert tiled[2] == pytest.approx(whole[2], rel=1e-14)
    assert whole[1] == len(np.unique(np.floor(place(pts, poses) / CELL), axis=0))
    assert (whole[2], whole[3]) == pytest.approx(brute_force_revisit(pts, poses), rel=1e-12)


def test_tiles_cover_every_placed_point_once(monkeypatch):
    monkeypatch.setattr(consistency, "TILE_POINTS", 300)
    pts, poses = multi_place_case(3)
    cells = consistency.cell_index(place(pts, poses))
    owners = sum(consistency.inside(cells, lo, hi).astype(int) for lo, hi in consistency.tiles(pts, poses))
    assert np.all(owners == 1)


def circling_store(laps: int) -> ScanStore:
    """A laser circling a room ``laps`` times, 50 scans of 500 random ranges a lap (25,000 end
    points a lap, over the same area whatever the laps)."""
    rng = np.random.default_rng(5)
    store = ScanStore()
    angles = np.linspace(-1.5, 1.5, 500)
    for i in range(50 * laps):
        a = 2 * math.pi * i / 50
        r = rng.uniform(2.0, 8.0, 500)
        store.add(
            np.array([10 * math.cos(a), 10 * math.sin(a), a + math.pi / 2]),
            np.column_stack((r * np.cos(angles), r * np.sin(angles))),
        )
    return store


def traced_consistency(store: ScanStore) -> tuple[MapConsistency, int]:
    """The store's consistency (odometry 1 cm and 1 mrad off) and the peak of its allocations."""
    tracemalloc.start()
    try:
        got = consistency.store_consistency(store, store.poses() + [0.01, 0.0, 0.001])
        return got, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_store_consistency_memory_is_flat_in_the_log_length(monkeypatch):
    """Placed 2,500 points at a time in tiles of 2,500: four times the laps over the same room (4×
    the points) peak within 1.3× the allocations of one lap, and below half of one float64
    copy of the points (the figures once took some 50 bytes a point); a store's figures are those
    of its scans given as a list."""
    monkeypatch.setattr(consistency, "TILE_POINTS", 2_500)
    monkeypatch.setattr(consistency, "CHUNK", 2_500)
    one, four = circling_store(1), circling_store(4)
    got_one, peak_one = traced_consistency(one)
    got_four, peak_four = traced_consistency(four)
    assert got_four.points == four.n_points == 100_000 and got_four.revisit_share > 0.5
    assert peak_four < 1.3 * peak_one and peak_four < 16 * four.n_points / 2, (peak_one, peak_four)
    odoms = one.poses() + [0.01, 0.0, 0.001]
    listed = map_consistency(one.in_laser_frame(), one.poses(), odoms)
    np.testing.assert_equal(dataclasses.asdict(got_one), dataclasses.asdict(listed))  # NaN == NaN
