"""ATE/RPE/relation metrics against hand-computed values on tiny trajectories."""

import json
import os

import numpy as np
import pytest
from scipy import optimize

from cornerslam_cli.errors import LogError
from cornerslam_cli.evaluate import (
    align_se2,
    align_sim2,
    apply_se2,
    ate,
    in_holes,
    inside_span,
    relation_error,
    relation_errors,
    rpe,
    sparse_note,
)
from cornerslam_cli.geometry import relative


def square(n=40):
    t = np.arange(n, dtype=float)
    s = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return t, np.column_stack((5 * np.cos(s), 3 * np.sin(s), s + np.pi / 2))


def test_ate_is_zero_for_a_rigidly_moved_copy():
    t, gt = square()
    est = apply_se2(0.7, np.array([3.0, -2.0]), gt)
    r = ate(t, est, t, gt)
    assert r.rmse == pytest.approx(0.0, abs=1e-9) and r.n == len(t)


def test_ate_of_a_constant_offset_in_one_axis_after_alignment():
    # gt visits each point of a line twice; est is off by +d then -d at each: symmetric, so no
    # rotation or translation can remove it and the RMSE is d
    t = np.arange(10.0)
    gt = np.column_stack((np.repeat(np.arange(5.0), 2), np.zeros(10), np.zeros(10)))
    est = gt.copy()
    est[:, 1] = np.where(np.arange(10) % 2 == 0, 0.1, -0.1)
    r = ate(t, est, t, gt)
    assert r.rmse == pytest.approx(0.1, rel=1e-6)
    assert r.max == pytest.approx(0.1, rel=1e-6)


def test_align_se2_recovers_a_known_transform():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(30, 2))
    ang, t = 0.3, np.array([1.0, 2.0])
    c, s = np.cos(ang), np.sin(ang)
    b = a @ np.array([[c, -s], [s, c]]).T + t
    ang2, t2 = align_se2(a, b)
    assert ang2 == pytest.approx(ang) and t2 == pytest.approx(t)


def test_align_sim2_recovers_a_known_similarity_and_matches_a_numerical_fit():
    rng = np.random.default_rng(2)
    a = rng.normal(size=(40, 2)) * 5
    scale, ang, t = 1.003, -2.9, np.array([-3.0, 0.5])
    c, s = np.cos(ang), np.sin(ang)
    b = scale * a @ np.array([[c, -s], [s, c]]).T + t
    s2, ang2, t2 = align_sim2(a, b)
    assert s2 == pytest.approx(scale, abs=1e-12) and ang2 == pytest.approx(ang) and t2 == pytest.approx(t)
    # with noise: the closed form is the least-squares optimum a general solver finds
    b = b + rng.normal(scale=0.1, size=b.shape)

    def residual(p):
        c, s = np.cos(p[1]), np.sin(p[1])
        return (p[0] * a @ np.array([[c, -s], [s, c]]).T + p[2:] - b).ravel()

    fit = optimize.least_squares(residual, [1.0, -2.5, 0.0, 0.0], xtol=1e-14, ftol=1e-14, gtol=1e-14)
    s2, ang2, t2 = align_sim2(a, b)
    assert [s2, ang2, *t2] == pytest.approx(list(fit.x), abs=1e-7)


def test_ate_with_correct_scale_removes_a_scale_and_reports_it():
    t = np.arange(50.0)
    gt = np.column_stack((np.cos(t / 8) * 10, np.sin(t / 5) * 6, t / 8))
    est = gt * [0.99, 0.99, 1.0]  # every distance 1 % short
    plain = ate(t, est, t, gt)
    scaled = ate(t, est, t, gt, correct_scale=True)
    assert plain.scale is None and plain.rmse > 0.02
    assert scaled.scale == pytest.approx(1 / 0.99) and scaled.rmse == pytest.approx(0.0, abs=1e-9)
    assert scaled.rot_rmse == pytest.approx(0.0, abs=1e-12)


def test_correct_scale_of_a_trajectory_that_does_not_move_is_refused_not_nan():
    """A trajectory whose positions are all one point has no scale (Σ‖a_i‖² = 0): refused naming why,
    not a NaN ATE with a RuntimeWarning (the plain ATE is still the reference's spread)."""
    t = np.arange(20.0)
    gt = np.column_stack((t * 0.01, np.zeros(20), np.zeros(20)))
    est = np.tile([1.0, 2.0, 0.0], (20, 1))
    assert ate(t, est, t, gt).rmse == pytest.approx(np.std(gt[:, 0]))
    with pytest.raises(LogError, match="one point"):
        align_sim2(est[:, :2], gt[:, :2])
    with pytest.raises(LogError, match="one point"):
        ate(t, est, t, gt, correct_scale=True)


def test_correct_scale_against_a_ground_truth_that_does_not_move_is_refused_not_zero():
    """A reference whose positions are all one point: the best scale is 0, which shrank the whole
    trajectory onto that point and printed a perfect ATE 0.0000 m (×0.00000), exit 0; refused now."""
    t = np.arange(20.0)
    est = np.column_stack((t * 0.1, np.zeros(20), np.zeros(20)))
    gt = np.tile([5.0, 5.0, 0.0], (20, 1))
    assert ate(t, est, t, gt).rmse == pytest.approx(np.std(est[:, 0]))  # the plain ATE stays
    with pytest.raises(LogError, match="ground truth's positions .* all one point"):
        ate(t, est, t, gt, correct_scale=True)


def test_rpe_per_step_of_a_scaled_trajectory():
    t = np.arange(11.0)
    gt = np.column_stack((t, np.zeros(11), np.zeros(11)))
    est = gt * [1.1, 1, 1]  # each 1 m step measured as 1.1 m
    r = rpe(t, est, t, gt, delta_m=2.0)
    assert r.rpe_step_rmse == pytest.approx(0.1)
    assert r.rpe_per_m == pytest.approx(0.1)


def test_relation_error_with_time_offset_and_interpolation():
    t = np.array([0.0, 1.0, 2.0])
    est = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    off = 100.0
    # relation 0.5 → 1.5: truth says 1.2 m forward; estimate says 1.0 m: error 0.2 m
    rel = np.array(
        [[100.5, 101.5, 1.2, 0.0, 0.0], [100.0, 102.0, 2.0, 0.0, np.radians(10)], [50, 51, 0, 0, 0]]
    )
    e = relation_error(t, est, rel, time_offset=off)
    assert e.n == 2 and e.n_total == 3
    assert e.trans_mean == pytest.approx(0.1)
    assert e.rot_mean_deg == pytest.approx(5.0)
    inside, trans, rot = relation_errors(t, est, rel, time_offset=off)
    assert inside.tolist() == [True, True, False]
    assert trans == pytest.approx([0.2, 0.0]) and rot == pytest.approx([0.0, 10.0])
    assert relation_error(t, est, rel[2:], time_offset=off).n == 0  # none inside: nothing to score


# ---------------------------------------------------------------------------- files as users give them
def circle(n: int = 200, t0: float = 1_700_000_000.0) -> tuple[np.ndarray, np.ndarray]:
    """n poses 0.1 s apart on a circle of radius 3 m (30 m of path)."""
    t = t0 + 0.1 * np.arange(n)
    a = np.linspace(0.0, 2 * np.pi, n)
    return t, np.column_stack((3 * np.cos(a), 3 * np.sin(a), a + np.pi / 2))


@pytest.fixture
def files(tmp_path):
    """A trajectory (the circle with seeded noise) and its ground truth, as TUM files."""
    from cornerslam_cli.report.tables import write_tum

    t, gt = circle()
    est = gt + np.random.default_rng(3).normal(0.0, 0.01, gt.shape)
    write_tum(tmp_path / "est.tum", t, est)
    write_tum(tmp_path / "gt.tum", t, gt)
    return tmp_path / "est.tum", tmp_path / "gt.tum"


def evaluate(*args):
    from click.testing import CliRunner

    from cornerslam_cli.cli import cli

    return CliRunner().invoke(cli, ["evaluate", *map(str, args)], catch_exceptions=False)


def rewrite(path, edit) -> None:
    rows = path.read_text().splitlines()
    path.write_text("\n".join(edit(rows)) + "\n")


def swap(rows: list[str], i: int = 2, j: int = 150) -> list[str]:
    rows = list(rows)
    rows[i], rows[j] = rows[j], rows[i]
    return rows


@pytest.mark.parametrize("which", ["gt", "est"])
def test_lines_out_of_time_order_are_sorted_not_misread(files, which):
    """Two swapped lines (the issue: 0.995 m reported instead of 0.012 m): the same figures as the
    sorted file, and a warning naming the file and lines."""
    est, gt = files
    before = evaluate(est, "--ground-truth", gt)
    assert before.exit_code == 0 and "ATE  rmse 0.01" in before.output
    rewrite(gt if which == "gt" else est, swap)
    after = evaluate(est, "--ground-truth", gt)
    assert after.exit_code == 0, after.output
    assert after.stdout == before.stdout
    assert "is not in time order (line 4 at" in after.stderr and "sorted by stamp" in after.stderr


def test_repeated_lines_are_dropped_and_two_poses_at_one_stamp_refused(files):
    est, gt = files
    before = evaluate(est, "--ground-truth", gt).stdout
    rewrite(gt, lambda rows: [*rows[:10], rows[9], *rows[10:]])
    res = evaluate(est, "--ground-truth", gt)
    assert res.stdout == before and "repeats 1 line(s) (first: line 11): dropped" in res.stderr
    rewrite(gt, lambda rows: [*rows[:20], rows[20].replace(" 0 0 0 ", " 0 0 0.3 ", 1), *rows[20:]])
    res = evaluate(est, "--ground-truth", gt)
    assert res.exit_code == 2 and "two different poses at stamp" in res.stderr
    assert "(lines 21 and 22)" in res.stderr and "Traceback" not in res.output


def scale_quaternions(rows: list[str], k: float) -> list[str]:
    return [" ".join([*r.split()[:4], *(f"{k * float(v):.9f}" for v in r.split()[4:])]) for r in rows]


def test_ground_truth_quaternions_are_normalised_and_zero_ones_refused(files):
    """A ground truth whose quaternions are ×2 scores as the unit one (the yaw formula assumes unit
    length: RPE was off); an all-zero quaternion has no orientation: exit 2 naming the line."""
    est, gt = files
    unit = evaluate(est, "--ground-truth", gt)
    rewrite(gt, lambda rows: scale_quaternions(rows, 2.0))
    res = evaluate(est, "--ground-truth", gt)
    assert res.exit_code == 0 and res.output == unit.output, (res.output, unit.output)
    rewrite(gt, lambda rows: [*rows[:5], *scale_quaternions(rows[5:6], 0.0), *rows[6:]])
    res = evaluate(est, "--ground-truth", gt)
    assert res.exit_code == 2 and "line 6 has a zero-length quaternion" in res.stderr, res.output


def test_ground_truth_that_does_not_overlap_is_exit_2_not_nan(files):
    est, gt = files
    rewrite(gt, lambda rows: [" ".join([f"{float(r.split()[0]) + 100:.9f}", *r.split()[1:]]) for r in rows])
    res = evaluate(est, "--ground-truth", gt)
    assert res.exit_code == 2 and "nan" not in res.output.lower()
    assert "does not overlap the trajectory: 0 of its 200 poses" in res.stderr


def test_a_single_pose_trajectory_is_refused_as_such_not_as_no_overlap(files):
    """A one-scan run (`--max-scans 1`) inside the ground truth's span: the error said the ground truth
    "does not overlap the trajectory: 1 of its 1 poses fall within" its span, and asked whether it
    was the log's ground truth."""
    est, gt = files
    rewrite(est, lambda rows: rows[5:6])
    res = evaluate(est, "--ground-truth", gt)
    assert res.exit_code == 2 and "\n" not in res.stderr.strip(), res.output
    assert "the trajectory has a single pose: ATE and RPE against ground truth" in res.stderr
    assert "need two or more (process more scans)" in res.stderr
    assert "overlap" not in res.stderr and "this log's ground truth" not in res.stderr


@pytest.mark.parametrize("which", ["ground truth", "trajectory"])
def test_a_file_stamped_in_nanoseconds_is_named_as_such(files, which):
    """A ROS exporter's integer nanosecond stamps in a TUM file: said, not "does not overlap" — of the
    trajectory too (a probe: the error blamed the ground truth, "is it this log's ground truth?")."""
    est, gt = files

    def in_ns(rows):
        return [f"{round(float(r.split()[0]) * 1e9)} {' '.join(r.split()[1:])}" for r in rows]

    rewrite(gt if which == "ground truth" else est, in_ns)
    res = evaluate(est, "--ground-truth", gt)
    assert res.exit_code == 2 and "\n" not in res.stderr.strip(), res.output
    named = gt if which == "ground truth" else est
    assert f"{which} '{named}' has its stamps in nanoseconds, not seconds" in res.stderr
    assert "(write its stamps in seconds)" in res.stderr and "overlap" not in res.stderr


@pytest.mark.parametrize(
    "content, fragment",
    [
        (np.random.default_rng(0).bytes(3000), "is a binary file"),
        ("1 2 3 4 5 6 7 8\n".encode("utf-16"), "is UTF-16 text"),
        (b"# \xe9t\xe9\n1 2 3 4 5 6 7 8\n", "is not UTF-8 text (byte 0xe9 at line 1)"),
        (b"1 2 3 4 5 6 7 8\n2 nan 3 4 5 6 7 8\n", "line 2 has a value that is not finite"),
        (b"1 2 3 4 5 6 7 8\n2 inf 3 4 5 6 7 8\n", "line 2 has a value that is not finite"),
        (b"", "has no"),
    ],
    ids=["binary", "utf16", "latin1", "nan", "inf", "empty"],
)
@pytest.mark.parametrize("option", ["--ground-truth", "--relations"])
def test_bad_reference_files_are_exit_2_naming_the_file(files, tmp_path, option, content, fragment):
    est, _ = files
    bad = tmp_path / "bad.txt"
    bad.write_bytes(content)
    res = evaluate(est, option, bad)
    assert res.exit_code == 2, res.output
    assert res.stderr.startswith("error: ") and "bad.txt" in res.stderr and fragment in res.stderr


def test_relations_in_any_order_and_partly_outside(files, tmp_path):
    """Relations stand alone: shuffled rows score the same; those outside the trajectory are not
    counted (n of n_total); none inside is exit 2."""
    est, gt = files
    t, g = circle()
    i = np.arange(0, 190, 10)
    rel = relative(g[i], g[i + 10])
    rows = [
        f"{t[a]:.6f} {t[a + 10]:.6f} {x:.6f} {y:.6f} 0 0 0 {th:.6f}"
        for a, (x, y, th) in zip(i, rel, strict=True)
    ]
    rows += ["1.0 2.0 0 0 0 0 0 0", f"{t[5]:.6f} {t[-1] + 50:.6f} 1 0 0 0 0 0"]  # wholly / partly outside
    path = tmp_path / "r.relations"
    path.write_text("\n".join(rows) + "\n")
    first = evaluate(est, "--relations", path)
    assert first.exit_code == 0 and f"({len(i)}/{len(rows)} relations)" in first.stdout
    path.write_text("\n".join(rows[::-1]) + "\n")
    assert evaluate(est, "--relations", path).stdout == first.stdout
    res = evaluate(est, "--relations", path, "--time-offset", 1e6)
    assert res.exit_code == 2 and "falls inside the trajectory's time span" in res.stderr


def test_rpe_per_metre_is_a_dash_when_the_path_is_shorter_than_a_metre(tmp_path):
    from cornerslam_cli.report.tables import write_tum

    t, g = circle(4)
    g[:, :2] *= 0.01  # 4 poses on a circle of 3 cm
    write_tum(tmp_path / "gt.tum", t, g)
    res = evaluate(tmp_path / "gt.tum", "--ground-truth", tmp_path / "gt.tum")
    assert res.exit_code == 0 and "per metre - m/m" in res.stdout and "nan" not in res.stdout


@pytest.mark.parametrize(
    ("kind", "runs", "each"),
    [("compare", ["icnn", "pca"], "associator"), ("batch", ["a__pca", "b__pca"], "combination")],
)
def test_a_compare_or_batch_directory_names_the_run_directories_to_evaluate(
    files, tmp_path, kind, runs, each
):
    """`evaluate` pointed at a compare (or batch) output: it holds one run directory per associator
    (combination), not a trajectory — exit 2 naming them (it said trajectory.tum does not exist)."""
    import shutil

    from cornerslam_cli.report.ownership import mark_output

    est, gt = files
    out = tmp_path / "out"
    for name in runs:
        (out / name).mkdir(parents=True)
        shutil.copy(est, out / name / "trajectory.tum")
        mark_output(out / name, "run")
    (out / "notes").mkdir()  # a directory that is no run is not offered
    mark_output(out, kind)
    res = evaluate(out, "--ground-truth", gt)
    assert res.exit_code == 2, res.output
    assert res.stderr == (
        f"error: '{out}' is a cornerslam {kind} output: it holds one run directory per {each} "
        f"({', '.join(runs)}) (evaluate one of them with the same options: e.g. cornerslam evaluate "
        f"{out / runs[0]})\n"
    )
    res = evaluate(out / runs[1], "--ground-truth", gt)
    assert res.exit_code == 0 and "ATE" in res.output, res.output


def test_a_single_pose_ground_truth_is_refused_as_such_not_as_no_overlap(files):
    """A ground truth of one line (a cut file, a header-only export plus one pose): the error said it
    "does not overlap the trajectory: 1 of its 200 poses fall within" its span (x to x s) and asked
    whether it was the log's ground truth."""
    est, gt = files
    rewrite(gt, lambda rows: rows[5:6])
    res = evaluate(est, "--ground-truth", gt)
    assert res.exit_code == 2 and "\n" not in res.stderr.strip(), res.output
    assert "has a single pose: ATE and RPE need two or more" in res.stderr, res.stderr
    assert "overlap" not in res.stderr and "this log's ground truth" not in res.stderr


@pytest.mark.parametrize("option", ["--ground-truth", "--relations", "trajectory"])
def test_stamps_too_large_to_score_are_refused_naming_the_line(files, tmp_path, option):
    """Stamps of ±1.7e308 s: every interpolation overflowed into "ATE rmse nan m" under numpy's warnings,
    exit 0 (a probe). (Nanoseconds since 1970 still pass, to be said to be nanoseconds: test above.)"""
    est, gt = files
    t = [r.split()[0] for r in est.read_text().splitlines()]
    if option == "--relations":
        bad = tmp_path / "bad.relations"
        bad.write_text(f"{t[1]} {t[5]} 0.1 0 0 0 0 0\n{t[2]} 1.7e308 0.1 0 0 0 0 0\n")
        res = evaluate(est, option, bad)
    else:
        bad = gt if option == "--ground-truth" else est
        rewrite(bad, lambda rows: [*rows[:3], " ".join(["1.7e308", *rows[3].split()[1:]]), *rows[4:]])
        res = evaluate(est, "--ground-truth", gt)
    assert res.exit_code == 2, res.output
    assert f"'{bad}' line {2 if option == '--relations' else 4} has a stamp beyond ±1e+19 s" in res.stderr
    assert "nan" not in res.output and "RuntimeWarning" not in res.output


def test_the_first_line_too_far_is_named_whether_its_stamp_or_its_position(files):
    """A far position on line 2 and a far stamp on line 4: line 2 is named (stamps were checked first)."""
    est, gt = files

    def damage(rows):
        rows = list(rows)
        rows[1] = " ".join([rows[1].split()[0], "1e12", *rows[1].split()[2:]])
        rows[3] = " ".join(["1e300", *rows[3].split()[1:]])
        return rows

    rewrite(gt, damage)
    res = evaluate(est, "--ground-truth", gt)
    assert res.exit_code == 2 and f"'{gt}' line 2 has a position beyond ±1e+09 m" in res.stderr, res.output


@pytest.mark.parametrize("option", ["--ground-truth", "--relations", "trajectory"])
def test_positions_too_large_to_score_are_refused_naming_the_line(files, tmp_path, option):
    """A position of 1e308 m (a corrupted or mis-scaled file): evaluate printed "ATE rmse inf m" or
    "translation inf ± nan m" under numpy's overflow warnings and exited 0."""
    est, gt = files
    t = [r.split()[0] for r in est.read_text().splitlines()]
    if option == "--relations":
        bad = tmp_path / "bad.relations"
        bad.write_text(f"{t[1]} {t[5]} 0.1 0 0 0 0 0\n{t[2]} {t[6]} 1e308 0 0 0 0 0\n")
        res = evaluate(est, option, bad)
    else:
        bad = gt if option == "--ground-truth" else est
        rewrite(
            bad,
            lambda rows: [
                *rows[:3],
                " ".join([rows[3].split()[0], "1e308", *rows[3].split()[2:]]),
                *rows[4:],
            ],
        )
        res = evaluate(est, "--ground-truth", gt)
    assert res.exit_code == 2, res.output
    assert f"'{bad}' line {2 if option == '--relations' else 4} has a position beyond ±1e+09 m" in res.stderr
    assert "inf" not in res.output and "RuntimeWarning" not in res.output


def detour(t: np.ndarray) -> np.ndarray:
    """A path along x at 1 m/s that leaves the line for a 2 m bump between 10 and 15 s."""
    y = np.where((t > 10) & (t < 15), 2.0 * np.sin(np.pi * (t - 10) / 5) ** 2, 0.0)
    return np.column_stack((t, y, np.zeros_like(t)))


def test_ground_truth_is_not_interpolated_across_a_hole():
    """A motion capture at 100 Hz loses the robot for the 5 s of its detour: estimates there (exact
    ones) were scored against the straight line between the hole's ends (0.47 m RMSE); they are now
    left out and counted, and the rest scores 0. A pose within 10 ms of either end is still scored."""
    gt_t = np.round(np.arange(0.0, 30.0, 0.01), 6)
    gt_t = gt_t[(gt_t <= 10.0) | (gt_t >= 15.0)]
    t = np.arange(0.0, 30.0, 0.1)
    r = ate(t, detour(t), gt_t, detour(gt_t))
    inside = (t > 10.0 + 0.01) & (t < 15.0 - 0.01)
    assert r.rmse == pytest.approx(0.0, abs=1e-9) and r.in_holes == int(inside.sum()) == 49
    assert r.n == len(t) - 49
    assert rpe(t, detour(t), gt_t, detour(gt_t)).rpe_step_rmse < 0.02  # the pair across the hole: 0.01 m


def test_a_reference_with_poses_only_where_the_robot_moved_is_scored_at_them():
    """radish's references hold one pose per scan, with gaps of up to minutes where the robot stood
    still: a trajectory of those scans has its stamps on them, and every pose is scored."""
    rng = np.random.default_rng(0)
    t = np.cumsum(rng.choice([0.5, 0.5, 2.0, 40.0], size=60))
    gt = np.column_stack((np.cumsum(np.ones(60)), np.zeros(60), np.zeros(60)))
    est = gt + [0.1, 0.0, 0.0] * (np.arange(60)[:, None] % 2)
    r = ate(t, est, t, gt)
    assert r.n == 60 and r.in_holes is None and r.rmse > 0.04


def test_a_trajectory_wholly_in_a_hole_of_the_ground_truth_is_exit_2(tmp_path):
    """Every pose inside the ground truth's span but in one of its gaps: nothing to score, and said so
    (it used to score them against a straight line)."""
    from cornerslam_cli.report.tables import write_tum

    gt_t = np.concatenate((np.arange(0.0, 10.0, 0.01), np.arange(20.0, 30.0, 0.01)))
    t = np.arange(12.0, 18.0, 0.1)
    write_tum(tmp_path / "gt.tum", gt_t, detour(gt_t))
    write_tum(tmp_path / "est.tum", t, detour(t))
    res = evaluate(tmp_path / "est.tum", "--ground-truth", tmp_path / "gt.tum")
    assert res.exit_code == 2 and "nan" not in res.output.lower(), res.output
    assert "60 of the 60 poses within its time span fall in its gaps" in res.stderr
    # one pose out of the hole: still nothing to score (two are needed), the same error
    t2 = np.concatenate(([5.0], t))
    write_tum(tmp_path / "est.tum", t2, detour(t2))
    res = evaluate(tmp_path / "est.tum", "--ground-truth", tmp_path / "gt.tum")
    assert res.exit_code == 2 and "60 of the 61 poses" in res.stderr, res.output
    t3 = np.concatenate(([5.0, 6.0], t))
    write_tum(tmp_path / "est.tum", t3, detour(t3))
    res = evaluate(tmp_path / "est.tum", "--ground-truth", tmp_path / "gt.tum")
    assert res.exit_code == 0 and "(n=2; 60 in gaps of the ground truth not scored)" in res.output, res.output


@pytest.mark.parametrize("where", ["start", "end"])
def test_a_hole_at_an_end_of_the_ground_truth_counts_only_poses_within_its_span(tmp_path, where):
    """A ground truth whose first (or last) gap is a hole, and a trajectory running on beyond that end
    of it: the poses outside its span are outside, not in the hole. They were counted as in it, so the
    102 poses the ground truth does cover were refused with exit 2 ("599 of the 201 poses within its
    time span fall in its gaps")."""
    from cornerslam_cli.report.tables import write_tum

    t = np.round(np.arange(50.0, 120.0001, 0.1), 6)
    dense = np.round(np.arange(110.0, 120.0001, 0.1), 6) if where == "start" else np.round(t[t <= 60.0], 6)
    gt_t = np.concatenate(([100.0], dense)) if where == "start" else np.concatenate((dense, [70.0]))
    write_tum(tmp_path / "gt.tum", gt_t, detour(gt_t))
    write_tum(tmp_path / "est.tum", t, detour(t))
    res = evaluate(tmp_path / "est.tum", "--ground-truth", tmp_path / "gt.tum")
    assert res.exit_code == 0, res.output
    assert "(n=102; 99 in gaps of the ground truth not scored)" in res.output, res.output
    r = ate(t, detour(t), gt_t, detour(gt_t))
    assert r.n == 102 and r.in_holes == 99
    assert not np.any(in_holes(gt_t, t) & ~inside_span(gt_t, t))


def test_a_ground_truth_of_few_poses_far_from_the_trajectorys_is_warned_about(tmp_path):
    """Two ground-truth poses 20 s apart (or one every 5 s): no gap is a hole by the median spacing, so
    the poses between are scored against the straight line between them — said so, with how many; a
    ground truth every 2 s (no scored pose over 1 s from one of it) and radish's one per scan: silent."""
    from cornerslam_cli.report.tables import write_tum

    t = np.round(np.arange(0.0, 20.0001, 0.1), 6)
    write_tum(tmp_path / "est.tum", t, detour(t))
    for gt_t, far in (
        ([0.0, 20.0], 179),
        (np.arange(0.0, 20.0001, 5.0), 116),
        (np.arange(0.0, 20.0001, 2.0), 0),
    ):
        gt_t = np.asarray(gt_t, dtype=float)
        write_tum(tmp_path / "gt.tum", gt_t, detour(gt_t))
        res = evaluate(tmp_path / "est.tum", "--ground-truth", tmp_path / "gt.tum")
        assert res.exit_code == 0, res.output
        said = (
            f"is sparse: {far} of the 201 trajectory poses it scores lie more than 1 s from every one of its"
        )
        assert said in res.stderr if far else "is sparse" not in res.stderr, res.stderr
    assert sparse_note("gt", t, t) is None


def test_a_ground_truth_covering_part_of_the_trajectory_is_warned_about(files):
    """evaluate says what run says (its summary's warning) when the ground truth covers only part of the
    trajectory: how many poses were scored of how many, and why the rest were not; a whole one: silent."""
    est, gt = files
    whole = evaluate(est, "--ground-truth", gt)
    assert whole.exit_code == 0 and "covers" not in whole.stderr
    n = len(gt.read_text().splitlines())
    rewrite(gt, lambda rows: rows[: len(rows) // 2])
    res = evaluate(est, "--ground-truth", gt)
    assert res.exit_code == 0, res.output
    assert f"covers {n // 2} of the trajectory's {n} poses ({n - n // 2} outside its time span" in res.stderr
    assert f"ATE/RPE are over those {n // 2} only" in res.stderr


def test_relations_of_one_instant_or_a_yaw_beyond_pi_are_warned_about(tmp_path, caplog):
    """t1 = t2 on every line, or yaws in degrees: scored silently (0.323 m, 94.5°; found by a
    hostile-user probe). Still scored as given, now warned about."""
    import logging

    from cornerslam_cli.evaluate import read_relations

    rel = tmp_path / "r.relations"
    rel.write_text("1.0 1.0 0.1 0 0 0 0 0.01\n2.0 3.0 0.5 0 0 0 0 90.0\n4.0 5.0 0.5 0 0 0 0 -0.2\n")
    with caplog.at_level(logging.WARNING, logger="cornerslam.evaluate"):
        r = read_relations(rel)
    assert r.shape == (3, 5)
    assert "1 of its 3 relations join an instant to itself (t1 = t2)" in caplog.text
    assert "1 of its 3 relations have a yaw beyond ±π rad (degrees?" in caplog.text
    caplog.clear()
    rel.write_text("1.0 2.0 0.1 0 0 0 0 3.1\n2.0 3.0 0.5 0 0 0 0 -3.14\n")
    with caplog.at_level(logging.WARNING, logger="cornerslam.evaluate"):
        read_relations(rel)
    assert caplog.text == ""


def test_relations_repeated_exactly_count_once_warned(tmp_path, caplog):
    """A relations file joined to itself (`cat a a`) was scored with every relation twice, nothing said
    (a hostile-user probe); a TUM ground truth's repeated lines were already dropped with a warning."""
    import logging

    from cornerslam_cli.evaluate import read_relations

    lines = ["2.0 3.0 0.5 0 0 0 0 0.1\n", "1.0 2.0 0.1 0 0 0 0 0.2\n", "1.0 2.0 0.1 0 0 0 0 0.25\n"]
    rel = tmp_path / "r.relations"
    rel.write_text("".join(lines + lines[:2]))
    with caplog.at_level(logging.WARNING, logger="cornerslam.evaluate"):
        r = read_relations(rel)
    np.testing.assert_array_equal(r[:, [0, 1, 4]], [[2, 3, 0.1], [1, 2, 0.2], [1, 2, 0.25]])  # file order
    assert "2 of its 5 relations repeat an earlier line exactly: counted once" in caplog.text
    # the pair 1 → 2 measured twice with other yaws (0.2, 0.25): both scored, said
    assert (
        "1 of its 3 relations repeat an earlier pair (t1, t2) with other values: each is scored"
        in caplog.text
    )


def test_a_ground_truth_stamp_with_underscores_or_other_digits_is_refused(tmp_path):
    """'1_700_000_002.5' was read as 1700000002.5 (Python's float takes underscores), moving that pose;
    a number in a text file is plain ASCII (found by a hostile-user probe)."""
    from cornerslam_cli.errors import LogError
    from cornerslam_cli.evaluate import read_tum

    for stamp in ("1_700_000_002.5", "١٧"):
        gt = tmp_path / "g.tum"
        gt.write_text(f"{stamp} 0 0 0 0 0 0 1\n1700000003 0 0 0 0 0 0 1\n")
        with pytest.raises(LogError, match="line 1 is not a TUM pose"):
            read_tum(gt, "ground truth")


def test_evaluate_without_a_reference_uses_the_runs_and_says_what_it_scored(sim_log, tmp_path):
    """`evaluate OUTDIR` alone said "give --ground-truth" although the run's summary.json names the
    ground truth it was scored against; and its report did not say which file was scored against what,
    aligned how (an evo user's unaligned evo_ape differs: a new-user walkthrough)."""
    import shutil

    from click.testing import CliRunner

    from cornerslam_cli.cli import cli

    log, gt, out = tmp_path / "sim.mcap", tmp_path / "sim.gt.tum", tmp_path / "run"
    shutil.copy(sim_log, log)
    shutil.copy(sim_log.with_suffix(".gt.tum"), gt)
    assert CliRunner().invoke(cli, ["run", str(log), "--out", str(out), "-q"]).exit_code == 0
    given = evaluate(out, "--ground-truth", gt)
    assert given.exit_code == 0
    assert given.stdout.splitlines()[-1] == (
        f"scored: {out / 'trajectory.tum'} against ground truth {gt} (SE(2)-aligned, as evo_ape -a)"
    )
    alone = evaluate(out)
    assert alone.exit_code == 0 and alone.stdout == given.stdout and alone.stderr == ""
    shifted = evaluate(out, "--time-offset", "5")  # no relations to shift: refused, as before (a review)
    assert shifted.exit_code == 2 and "--time-offset shifts the times of --relations" in shifted.stderr
    kept = gt.read_text()
    rewrite(gt, lambda rows: rows[:-1])  # one pose fewer: not the poses the run was scored against
    changed = evaluate(out)  # (another file of that name, or this one edited: not taken for the run's)
    assert changed.exit_code == 2
    assert f"('{gt}' here does not hold the poses the run was scored against)" in changed.stderr
    gt.unlink()
    gone = evaluate(out)
    assert gone.exit_code == 2 and "give --ground-truth FILE.tum or --relations FILE" in gone.stderr
    assert f"the run was scored against '{gt}', not found from here" in gone.stderr
    # an older version's run kept no sha256 of its poses: which file it was cannot be told, none taken
    gt.write_text(kept)
    import json

    s = json.loads((out / "summary.json").read_text())
    del s["hashes"]["ground_truth"]
    (out / "summary.json").write_text(json.dumps(s, indent=2))
    old = evaluate(out)
    assert old.exit_code == 2 and "kept no sha256 of its poses (an older version's run)" in old.stderr
    # its summary.json damaged or gone: said (a hostile-user probe: only "give --ground-truth …")
    (out / "summary.json").write_text("{")
    damaged = evaluate(out)
    said = f"(cannot read the run summary '{out / 'summary.json'}': "
    assert damaged.exit_code == 2 and said in damaged.stderr
    (out / "summary.json").unlink()
    none = evaluate(out)
    assert (
        none.exit_code == 2
        and f"('{out}' has no summary.json to name what the run was scored against" in none.stderr
    )


def test_evaluate_finds_a_runs_relative_ground_truth_only_from_where_it_ran(sim_log, tmp_path, monkeypatch):
    """The run names its ground truth as given, relative to where it ran: from elsewhere a file of that
    name with other poses was taken for it, scored with exit 0 (a review found it)."""
    import shutil

    from click.testing import CliRunner

    from cornerslam_cli.cli import cli

    here, elsewhere = tmp_path / "here", tmp_path / "elsewhere"
    for d in (here, elsewhere):
        (d / "logs").mkdir(parents=True)
    shutil.copy(sim_log, here / "logs" / "sim.mcap")
    shutil.copy(sim_log.with_suffix(".gt.tum"), here / "logs" / "sim.gt.tum")
    rows = (here / "logs" / "sim.gt.tum").read_text().splitlines()
    (elsewhere / "logs" / "sim.gt.tum").write_text("\n".join(rows[: len(rows) // 2]) + "\n")
    monkeypatch.chdir(here)
    assert (
        CliRunner().invoke(cli, ["run", "logs/sim.mcap", "--out", str(tmp_path / "run"), "-q"]).exit_code == 0
    )
    assert evaluate(tmp_path / "run").exit_code == 0
    monkeypatch.chdir(elsewhere)
    res = evaluate(tmp_path / "run")
    assert res.exit_code == 2 and "'logs/sim.gt.tum' here does not hold the poses" in res.stderr


def test_a_file_cut_mid_line_is_scored_without_its_last_line_said(files):
    """evaluate's refusal of a cut-short run says "score the file as it is", but a file cut mid-line then
    failed on its last line's count of values; a last line with too few values and no newline after it is
    left out, warned (one that ends with a newline is still an error: written so, not cut)."""
    est, gt = files
    text = est.read_text()
    whole = evaluate(est, "--ground-truth", gt)
    cut = text[: text.rindex("\n", 0, len(text) - 1) + 1] + text.splitlines()[-1][:12]  # 12 chars: 1 value
    est.write_text(cut)
    res = evaluate(est, "--ground-truth", gt)
    assert res.exit_code == 0, res.output
    n = len(text.splitlines())
    assert f"ends mid-line (line {n}: 1 of 8 values, no newline): left out" in res.stderr
    assert f"(n={n - 1})" in res.stdout and f"(n={n})" in whole.stdout
    est.write_text(cut + "\n")
    res = evaluate(est, "--ground-truth", gt)
    assert res.exit_code == 2 and f"line {n} has 1 values" in res.stderr


def test_a_cut_inside_a_number_is_a_cut_too_and_a_line_ending_in_cr_is_not(files):
    """Cut right after a minus sign (or an exponent's 'e'), the last line is no number at all: it was
    "not a TUM pose", exit 2 (a review found it); a short last line that ends with a CR (an old Mac's
    line end, or CRLF cut between the two) was written so, and is still an error."""
    est, gt = files
    text = est.read_text()
    last = text.splitlines()[-1]
    head = text[: text.rindex(last)]
    est.write_text(head + last.split()[0] + " -")
    res = evaluate(est, "--ground-truth", gt)
    assert res.exit_code == 0 and "ends mid-line" in res.stderr, res.output
    est.write_text(head + " ".join(last.split()[:3]) + "\r")
    res = evaluate(est, "--ground-truth", gt)
    assert res.exit_code == 2 and "has 3 values" in res.stderr


def test_a_kitti_pose_file_is_named_as_one(files, tmp_path):
    """12 values a line (a 3×4 pose matrix, no stamp: KITTI's format): said, as evo users bring them."""
    est, _ = files
    kitti = tmp_path / "kitti.txt"
    kitti.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 1 0 1 0 0 0 0 1 0\n")
    res = evaluate(est, "--ground-truth", kitti)
    assert res.exit_code == 2 and "line 1 has 12 values" in res.stderr
    assert "a KITTI pose file, which has no stamps? write it as TUM" in res.stderr


def test_rpe_leaves_out_the_pairs_across_a_hole_of_the_ground_truth():
    """A pair of scored poses with unscored ones between them (in a hole of the ground truth) is no step
    the reference saw: it counted as one, the RPE per step ~6× too large (a hostile-user probe). Checked
    against the pairs counted one by one."""
    from cornerslam_cli.evaluate import rpe

    rng = np.random.default_rng(4)
    t = np.arange(100.0)
    truth = np.column_stack((0.5 * t, np.sin(0.1 * t), 0.05 * t))
    est = truth + rng.normal(0.0, 0.01, truth.shape)
    est[31:60] += (5.0, -3.0, 1.0)  # wrong where the ground truth has no pose: not scored
    est[60:] += (0.3, 0.0, 0.0)  # drifted across the hole: the step across it is 0.3 m off
    keep = (t <= 30) | (t >= 60)
    got = rpe(t, est, t[keep], truth[keep], delta_m=2.0)
    steps = [k for k in range(99) if keep[k] and keep[k + 1]]
    err = [relative(relative(truth[k], truth[k + 1]), relative(est[k], est[k + 1])) for k in steps]
    step, rot = (
        np.sqrt(np.mean([f(e) for e in err])) for f in (lambda e: e[0] ** 2 + e[1] ** 2, lambda e: e[2] ** 2)
    )
    assert got.rpe_step_rmse == pytest.approx(step, rel=1e-12) and step < 0.03
    assert got.rpe_step_rot_rmse == pytest.approx(rot, rel=1e-12)
    scored = np.flatnonzero(keep)  # per metre: pairs 2 m of reference path apart, none across the hole
    g, e = truth[scored], est[scored]
    dist = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(g[:, :2], axis=0).T))))
    per_m = []
    for i in range(len(g)):
        j = next((j for j in range(i, len(g)) if dist[j] >= dist[i] + 2.0), None)
        if j is not None and scored[j] - scored[i] == j - i:
            d = relative(relative(g[i], g[j]), relative(e[i], e[j]))
            per_m.append(np.hypot(d[0], d[1]) / (dist[j] - dist[i]))
    assert got.rpe_per_m == pytest.approx(np.mean(per_m), rel=1e-12)


def test_evaluate_says_when_the_runs_ground_truth_has_a_name_that_is_not_utf8(sim_log, tmp_path):
    """summary.json keeps a name that is not UTF-8 with its bytes replaced (JSON holds Unicode), so
    `evaluate OUTDIR` could not open it and said it was "not found from here" (a hostile-user probe)."""
    import os
    import shutil

    from click.testing import CliRunner

    from cornerslam_cli.cli import cli

    stem = tmp_path / os.fsdecode(b"s\xe9x")
    shutil.copy(sim_log, f"{stem}.mcap")
    shutil.copy(sim_log.with_suffix(".gt.tum"), f"{stem}.gt.tum")
    out = tmp_path / "run"
    assert CliRunner().invoke(cli, ["run", f"{stem}.mcap", "--out", str(out), "-q"]).exit_code == 0
    res = evaluate(out)
    assert res.exit_code == 2 and "a name that is not UTF-8, not kept as it is" in res.stderr
    assert "--ground-truth" in res.stderr


@pytest.mark.parametrize(("shift", "scored"), [(0.004, 50), (-0.004, 50), (0.02, 49), (-0.02, 49)])
def test_a_pose_just_outside_the_ground_truths_span_is_scored_as_evo_matches_it(shift, scored):
    """A 100 Hz ground truth starting 3 ms after the first scan: the first pose was dropped as outside its
    span, where evo matches any pose within its 10 ms max_diff (an interoperability probe). Within
    GT_NEAR of an end a pose is scored against that end; farther, not."""
    from cornerslam_cli.evaluate import ate

    t = np.arange(50.0)
    truth = np.column_stack((0.3 * t, 0.1 * t, 0.02 * t))
    a = ate(t, truth, t + shift, truth)
    assert a.n == scored and a.rmse < 0.02


def test_evaluate_without_a_reference_scores_against_the_runs_relations_at_its_time_offset(sim_log, tmp_path):
    """A run scored with --relations only: `evaluate OUTDIR` said "give --ground-truth … or --relations"
    (a new-user walkthrough), then that summary.json did not keep --time-offset. It keeps it now, with the
    relations' sha256: evaluate scores against them at that offset, the run's own figure; a relations file
    changed since is not taken for them, and the error says so."""
    from click.testing import CliRunner

    from cornerslam_cli.cli import cli
    from cornerslam_cli.report.tables import read_tum
    from cornerslam_cli.results import RunSummary

    t, gt = read_tum(sim_log.with_suffix(".gt.tum"))
    rel = tmp_path / "sim.relations"
    pairs = [(i, i + 5) for i in range(0, len(t) - 5, 5)]
    offset = 1000.25  # relation time − log time
    rel.write_text("".join(f"{t[i] + offset} {t[j] + offset} {' '.join(map(str, relative(gt[i], gt[j])[:2]))}"
                           f" 0 0 0 {relative(gt[i], gt[j])[2]}\n" for i, j in pairs))  # fmt: skip
    log, out = tmp_path / "sim.mcap", tmp_path / "run"
    log.write_bytes(sim_log.read_bytes())  # (no sim.gt.tum beside it: relations only)
    args = ["run", str(log), "--out", str(out), "-q", "--relations", str(rel), "--time-offset", str(offset)]
    assert CliRunner().invoke(cli, args).exit_code == 0
    acc = RunSummary.read(out).accuracy
    assert acc.relations_time_offset == offset and acc.relations.n == len(pairs)
    res = evaluate(out)
    assert res.exit_code == 0, res.output
    again = evaluate(out, "--relations", str(rel), "--time-offset", str(offset))
    assert again.exit_code == 0 and res.stdout == again.stdout
    assert f"{acc.relations.trans_mean:.3f}" in res.stdout and f"{len(pairs)}" in res.stdout
    # a --time-offset given is used with them, not replaced by the recorded one (a review)
    other = evaluate(out, "--time-offset", str(offset + 5))
    explicit = evaluate(out, "--relations", str(rel), "--time-offset", str(offset + 5))
    assert other.exit_code == 0 and other.stdout == explicit.stdout != res.stdout
    moved_away = rel.rename(rel.with_suffix(".away"))  # not found from here, with a ground truth beside:
    (tmp_path / "sim.gt.tum").write_bytes(sim_log.with_suffix(".gt.tum").read_bytes())  # (not the run's)
    from cornerslam_cli.report.run_dir import recorded_reference

    rec = recorded_reference(out)  # its offset is not kept without the relations (a review: it was
    assert rec.relations is None and rec.time_offset == 0.0  # refused as a --time-offset without them)
    moved_away.rename(rel)
    rel.write_text(rel.read_text().replace(f"{t[0] + offset}", f"{t[1] + offset}", 1))  # one relation moved
    res = evaluate(out)
    assert res.exit_code == 2
    assert f"'{rel}' here does not hold the relations the run was scored against" in res.stderr


def test_evaluate_says_which_reference_of_the_run_it_left_out_and_the_offset_it_scored_at(sim_log, tmp_path):
    """A run scored against a ground truth and relations, the relations moved away since: `evaluate OUTDIR`
    scored the ground truth alone and said why only under -v (a hostile-user probe) — warned now; the
    relations given again without --time-offset (0) fall outside the run: the error names the run's offset."""
    from click.testing import CliRunner

    from cornerslam_cli.cli import cli
    from cornerslam_cli.report.tables import read_tum

    t, gt = read_tum(sim_log.with_suffix(".gt.tum"))
    rel, offset = tmp_path / "sim.relations", 1000.25
    rows = [(t[i] + offset, t[i + 5] + offset, relative(gt[i], gt[i + 5])) for i in range(0, len(t) - 5, 5)]
    rel.write_text("".join(f"{a} {b} {r[0]} {r[1]} 0 0 0 {r[2]}\n" for a, b, r in rows))
    out = tmp_path / "run"
    args = [
        "run",
        str(sim_log),
        "--out",
        str(out),
        "-q",
        "--relations",
        str(rel),
        "--time-offset",
        str(offset),
    ]
    assert CliRunner().invoke(cli, args).exit_code == 0
    both = evaluate(out)
    assert both.exit_code == 0 and "relation" in both.stdout.lower() and not both.stderr, both.output
    away = rel.rename(tmp_path / "elsewhere.relations")
    res = evaluate(out)
    assert res.exit_code == 0 and "ATE" in res.stdout, res.output
    assert f"not scored against (the run was scored against '{rel}', not found from here)" in res.stderr
    res = evaluate(out, "--relations", str(away))  # another name, the same relations
    assert res.exit_code == 2 and f"the run scored them at --time-offset {offset!r}: give it" in res.stderr
    res = evaluate(out, "--relations", str(away), "--time-offset", "3")  # a wrong one given: the same hint
    assert res.exit_code == 2 and f"the run scored them at --time-offset {offset!r}: give it" in res.stderr
    # not for other relations (by content), nor for a pipe (read once: opened again, it would wait), nor
    # where the run scored none of them itself (its offset fails too) (a review)
    from cornerslam_cli.report.run_dir import recorded_offset

    other = tmp_path / "other.relations"
    other.write_text(away.read_text().replace(f"{rows[0][0]}", f"{rows[0][0] + 0.5}", 1))
    assert recorded_offset(out, away) == offset and recorded_offset(out, other) is None
    res = evaluate(out, "--relations", str(other))
    assert res.exit_code == 2 and "the run scored them" not in res.stderr
    fifo = tmp_path / "pipe.relations"
    os.mkfifo(fifo)
    assert recorded_offset(out, fifo) is None
    args = ["run", str(sim_log), "--out", str(tmp_path / "none"), "-q", "--relations", str(away)]
    assert CliRunner().invoke(cli, [*args, "--time-offset", "5000", "--no-ground-truth"]).exit_code == 0
    assert recorded_offset(tmp_path / "none", away) is None


@pytest.mark.parametrize("which", ["ground truth", "trajectory"])
def test_two_clocks_are_not_taken_for_microseconds(files, which):
    """A log stamped in seconds since 1970 against a half-hour ground truth stamped from 0 (or the other
    way round): the stamps ÷ 10⁶ fall inside the other's span, and the error said "has its stamps in
    microseconds, not seconds (write its stamps in seconds)" of stamps that were seconds (a new-user
    probe). Read so they would come 1 µs apart: two clocks, said so."""
    est, gt = files

    t0 = float(est.read_text().split()[0])

    def epoch(rows):
        return [f"{1262304212.0 + float(r.split()[0]) - t0:.6f} {' '.join(r.split()[1:])}" for r in rows]

    def stretched(rows):  # stamped from 21 s, its span holding 1262 s
        return [f"{21.0 + (float(r.split()[0]) - t0) * 100.0:.6f} {' '.join(r.split()[1:])}" for r in rows]

    rewrite(est if which == "trajectory" else gt, epoch)
    rewrite(gt if which == "trajectory" else est, stretched)
    res = evaluate(est, "--ground-truth", gt)
    assert res.exit_code == 2 and "\n" not in res.stderr.strip(), res.output
    assert "microseconds" not in res.stderr and "does not overlap the trajectory" in res.stderr
    wall = f"trajectory '{est}'" if which == "trajectory" else f"ground truth '{gt}'"
    assert f"{wall} is stamped in wall-clock time (seconds since 1970)" in res.stderr


def test_a_nanosecond_ground_truth_at_1_khz_is_still_named_as_such():
    """Nanoseconds since 1970 read as float64 are 256 ns apart at best: a 1 kHz ground truth's spacing
    came out at 0.000999936 s, under the 1 ms the units reading first asked (a review), and the error
    said "does not overlap" instead of naming the nanoseconds."""
    from cornerslam_cli.evaluate import overlap_problem

    t0 = 1_700_000_000.0
    est = t0 + np.arange(0.0, 60.0, 0.1)
    gt = np.array([float(int(t0 * 1e9) + k * 1_000_000) for k in range(60_000)])
    why, hint = overlap_problem(est, gt, "gt.tum")
    assert (
        why.startswith("gt.tum has its stamps in nanoseconds, not seconds")
        and hint == "write its stamps in seconds"
    )


@pytest.mark.parametrize("gt_first", [True, False])
def test_a_ground_truth_stamped_from_0_is_not_taken_for_milliseconds(gt_first):
    """A log stamped 1000–1118 s against its ground truth exported from 0 (0–118 s): the log's stamps
    ÷ 1000 fall inside the ground truth's span, and the error said the trajectory — cornerslam's own
    output — "has its stamps in milliseconds" (an evo-user probe). Read so, 118 s became 0.118 s: two
    clocks, not units. A real unit error keeps the spans alike, and is still named."""
    from cornerslam_cli.evaluate import overlap_problem

    log = 1000.0 + np.arange(0.0, 118.0, 0.5)
    gt = log - 1000.0
    est_t, gt_t = (log, gt) if gt_first else (gt, log)
    why, hint = overlap_problem(est_t, gt_t, "gt.tum")
    assert "milliseconds" not in why and why.startswith("gt.tum does not overlap the trajectory"), why
    assert "Its stamps must use the log's clock" in hint
    why, hint = overlap_problem(log, log * 1e3, "gt.tum")  # the same span in ms: named
    assert why.startswith("gt.tum has its stamps in milliseconds, not seconds") and "seconds" in hint
    why, _ = overlap_problem(log, log[:20] * 1e3, "gt.tum")  # a ground truth of a tenth of the run, in ms
    assert why.startswith("gt.tum has its stamps in milliseconds, not seconds")
    # a review: a run of 30 s of a 600 s log against its whole ground truth in ns (and a ground truth of
    # 1/30 of the run in ms) were said not to overlap once the spans had to be alike: named again
    whole = 1.7e9 + np.arange(0.0, 600.0, 0.1)
    why, _ = overlap_problem(whole[:300], whole * 1e9, "gt.tum")
    assert why.startswith("gt.tum has its stamps in nanoseconds, not seconds"), why
    why, _ = overlap_problem(whole, whole[:200] * 1e3, "gt.tum")
    assert why.startswith("gt.tum has its stamps in milliseconds, not seconds"), why


def test_a_ground_truth_on_a_clock_100000_s_off_is_not_taken_for_milliseconds():
    """A part of a log thinned by distance (a scan every 2 s, 18-171 s) against its whole ground truth
    with every stamp 100,000 s later: read as ms, two of its poses fall in the run's span, inside 0.7 s
    where the run has no pose, and the error said milliseconds and to write them in seconds (a probe).
    Stamps read in another unit on weak evidence — none of the other file's inside their span, or over
    DENSER times as dense — are said as the other reading of two clocks; on good evidence, a unit."""
    from cornerslam_cli.evaluate import overlap_problem

    def two_clocks(why: str) -> bool:
        return why.startswith("gt.tum does not overlap the trajectory") and "(or a unit: " in why

    log = 18.0 + np.arange(0.0, 708.0, 2.07)
    why, hint = overlap_problem(log[:74], log + 100_000.0, "gt.tum")
    assert two_clocks(why) and "gt.tum's stamps read in milliseconds fall within" in why, why
    assert "Its stamps must use the log's clock" in hint
    # reviews: at 10 Hz the run has poses inside those 0.7 s — the ground truth read as ms is 1,000 times
    # as dense as the run; the mirror case, a sparse run 100,000 s ahead of a 10 Hz ground truth
    log = 18.0 + np.arange(0.0, 708.0, 0.1)
    assert two_clocks(overlap_problem(log[:1530], log + 100_000.0, "gt.tum")[0])
    why = overlap_problem(18.0 + np.arange(0.0, 150.0, 2.0) + 100_000.0, log, "gt.tum")[0]
    assert two_clocks(why) and "the trajectory's stamps read in milliseconds" in why, why
    # a 1 kHz motion capture in ms against a 10 Hz run: a unit; against a run a pose every 2 s, both said
    mocap = 1000.0 + np.arange(0.0, 20.0, 0.001)
    why, hint = overlap_problem(1000.0 + np.arange(0.0, 20.0, 0.1), mocap * 1e3, "gt.tum")
    assert (
        why.startswith("gt.tum has its stamps in milliseconds, not seconds")
        and hint == "write its stamps in seconds"
    )
    assert two_clocks(overlap_problem(1000.0 + np.arange(0.0, 20.0, 2.0), mocap * 1e3, "gt.tum")[0])
    # a trajectory in ms against a 1 Hz ground truth: 15 poses over 1.4 s, one ground-truth pose among them
    run = 1010.05 + np.arange(15) * 0.1
    why = overlap_problem(run * 1e3, 1000.0 + np.arange(100.0), "gt.tum")[0]
    assert two_clocks(why) and "the trajectory's stamps read in milliseconds" in why, why
    why = overlap_problem((1010.05 + np.arange(50) * 0.1) * 1e3, 1000.0 + np.arange(100.0), "gt.tum")[0]
    assert why.startswith("the trajectory has its stamps in milliseconds, not seconds"), why


def mirrored(rows: list[str]) -> list[str]:
    """TUM rows in a z-down frame (NED/FRD): y and the yaw negated (qx, qy, qz, qw of a pure yaw)."""
    out = []
    for r in rows:
        if not r.strip() or r.startswith("#"):
            out.append(r)
            continue
        t, x, y, z, qx, qy, qz, qw = (float(v) for v in r.split())
        out.append(f"{t:.6f} {x} {-y} {-z} {qx} {qy} {-qz} {qw}")
    return out


def test_a_ground_truth_in_a_mirrored_frame_is_refused_not_scored(files, sim_log, tmp_path):
    """A z-down ground truth (NED/FRD: PX4/MAVROS, motion capture) scored 300× evo's ATE with no word,
    as evo_ape -a (an evo-user probe): no rotation in the plane undoes a mirror. evaluate refuses it
    naming the fit it has mirrored; a run warns and scores nothing; a right one is scored as before."""
    from click.testing import CliRunner

    from cornerslam_cli.cli import cli

    est, gt = files
    rewrite(gt, mirrored)
    res = evaluate(est, "--ground-truth", gt)
    assert res.exit_code == 2 and "\n" not in res.stderr.strip(), res.output
    assert f"ground truth '{gt}' is in a mirrored frame (z down: NED/FRD?)" in res.stderr
    assert "negating its y and yaw" in res.stderr
    rewrite(gt, mirrored)  # (back as it was)
    assert evaluate(est, "--ground-truth", gt).exit_code == 0
    log = tmp_path / "sim.mcap"
    log.write_bytes(sim_log.read_bytes())
    log.with_suffix(".gt.tum").write_bytes(sim_log.with_suffix(".gt.tum").read_bytes())
    rewrite(log.with_suffix(".gt.tum"), mirrored)
    res = CliRunner().invoke(cli, ["run", str(log), "--out", str(tmp_path / "out"), "-q"])
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["accuracy"] is None
    assert any("is in a mirrored frame" in w and "no ATE/RPE" in w for w in summary["warnings"])


def test_correct_scale_scales_the_rpe_too(files, tmp_path):
    """`evaluate --correct-scale` scaled the ATE's trajectory and not the RPE's: a trajectory in mm gave
    its RPE in mm beside a scale-corrected ATE (an evo-user probe; evo_rpe -as scales both). A trajectory
    at half size, corrected, scores the RPE of the whole-size one."""
    from cornerslam_cli.evaluate import evaluate_files
    from cornerslam_cli.report.tables import read_tum, write_tum

    est, gt = files
    t, poses = read_tum(est)
    half = tmp_path / "half.tum"
    write_tum(half, t, poses * np.array([0.5, 0.5, 1.0]))
    whole = evaluate_files(est, gt, correct_scale=True)
    corrected = evaluate_files(half, gt, correct_scale=True)
    assert corrected.ate.scale == pytest.approx(2.0 * whole.ate.scale, rel=1e-9)
    assert corrected.rpe_step_rmse == pytest.approx(whole.rpe_step_rmse, rel=1e-6)
    assert evaluate_files(half, gt).rpe_step_rmse > 2.0 * whole.rpe_step_rmse  # (not corrected: half size)
    res = evaluate(half, "--ground-truth", gt, "--correct-scale")
    assert "per metre" in res.stdout and "(scale corrected ×" in res.stdout.splitlines()[1]
    # per metre is a ratio: a ground truth in mm, corrected, gives the metres' figure (a probe: 0.0226
    # against 0.0074 — its window was 1 mm of the ground truth's path)
    gt_t, gt_poses = read_tum(gt)
    mm = tmp_path / "mm.tum"
    write_tum(mm, gt_t, gt_poses * np.array([1000.0, 1000.0, 1.0]))
    in_mm = evaluate_files(est, mm, correct_scale=True)
    assert in_mm.rpe_per_m == pytest.approx(whole.rpe_per_m, rel=1e-6)
    assert in_mm.rpe_step_rmse == pytest.approx(1000.0 * whole.rpe_step_rmse, rel=1e-6)  # (in its units)


@pytest.mark.parametrize("factor, unit", [(1000.0, "millimetres"), (100.0, "centimetres")])
def test_a_ground_truth_in_other_units_is_refused_unless_scale_is_corrected(files, factor, unit):
    """A ground truth in millimetres scored an ATE of 18 km with no word (an evo-user probe): its path
    over the trajectory's stamps is 1000 times as long. Refused naming the unit; with --correct-scale
    (asked for) it is scored. A trajectory that went nowhere is no unit: not said to be one."""
    from cornerslam_cli.evaluate import units_problem
    from cornerslam_cli.report.tables import read_tum, write_tum

    est, gt = files
    t, poses = read_tum(gt)
    write_tum(gt, t, poses * np.array([factor, factor, 1.0]))
    res = evaluate(est, "--ground-truth", gt)
    assert res.exit_code == 2 and "\n" not in res.stderr.strip(), res.output
    assert "the ground truth goes" in res.stderr and f"— {unit}?" in res.stderr
    assert evaluate(est, "--ground-truth", gt, "--correct-scale").exit_code == 0
    e_t, e = read_tum(est)
    still = np.zeros_like(e) + e[0]
    assert units_problem(e_t, still, t, poses * factor, "gt", "the trajectory") is None
    assert units_problem(e_t, e * np.array([factor, factor, 1.0]), t, poses, "gt", "the trajectory")[
        0
    ].startswith("gt and the trajectory are in different units: over the same stamps the trajectory goes")
    # a robot standing still: the ground truth's jitter back and forth over 1 cm, the trajectory's over
    # two steps of the unit's times that: the paths in the unit's ratio, the extents not so: no unit
    n = len(e_t)
    jitter = np.zeros((n, 3))
    jitter[1::2, 0] = 1e-2
    wander = np.zeros((n, 3))
    wander[:, 0] = np.array([0.0, 1.0, 2.0, 1.0] * n)[:n] * 1e-2 * factor
    assert units_problem(e_t, wander, e_t, jitter, "gt", "the trajectory") is None
    assert units_problem(
        e_t, jitter * factor, e_t, jitter, "gt", "the trajectory"
    )  # (the same shape: a unit)


@pytest.mark.parametrize("drift", [-1.1, -0.7, 0.0, 0.7])
def test_a_drifting_estimate_is_scored_not_taken_for_a_mirrored_ground_truth(drift):
    """A review: a corridor bending 0.4 rad left over 30 m, the estimate drifting in heading (rad over the
    run) fitted the ground truth better mirrored, and was refused as "in a mirrored frame". The turns
    tell: a drift adds to each step's turn, a mirror negates it."""
    from cornerslam_cli.evaluate import mirror_problem

    n = 300
    t = np.arange(n) * 0.1
    heading = 0.4 * np.arange(n) / n + 1.2 * np.sin(np.arange(n) / 40.0)  # (turns enough to tell)

    def integrate(theta):
        xy = np.cumsum(0.1 * np.column_stack((np.cos(theta), np.sin(theta))), axis=0)
        return np.column_stack((xy, theta))

    gt = integrate(heading)
    est = integrate(heading + drift * np.arange(n) / n)
    assert mirror_problem(t, est, t, gt, "gt", "the trajectory") is None
    mirrored = gt * np.array([1.0, -1.0, -1.0])
    assert mirror_problem(t, est, t, mirrored, "gt", "the trajectory")[0].startswith(
        "gt is in a mirrored frame"
    )


def test_turns_either_side_of_half_a_turn_are_not_taken_for_a_mirror():
    """A probe: a simulated log at 0.1 Hz turned 164° where its ground truth turned -179.6° (= 180.4°):
    the turns, 17° apart, differed by 343° unwrapped, against 16° negated — its own ground truth was
    refused as in a mirrored frame."""
    from cornerslam_cli.evaluate import mirror_problem

    t = np.array([0.0, 10.0])
    gt, est = (np.array([[0.0, 0.0, 0.0], [1.0, 0.0, np.radians(turn)]]) for turn in (-179.6, 163.6))
    assert mirror_problem(t, est, t, gt, "gt", "the trajectory") is None


def test_a_run_stuck_in_place_is_not_taken_for_a_ground_truth_in_millimetres():
    """A review: an estimate that jittered 2 cm in all against a ground truth going 18 m read as a ground
    truth "in millimetres" — the failure a stuck run is, named as the reference's."""
    from cornerslam_cli.evaluate import units_problem

    t = np.arange(600) * 0.1
    gt = np.column_stack((0.03 * np.arange(600), np.zeros(600), np.zeros(600)))
    stuck = np.zeros((600, 3))
    stuck[:, 0] = 1e-5 * np.cumsum(np.random.default_rng(2).choice([-1.0, 1.0], 600))
    assert units_problem(t, stuck, t, gt, "gt", "the trajectory") is None
