"""Motion correction of scans (logs/deskew.py) against ray casting and closed-form motion, the beams'
times read from every log format, the synchroniser's velocity, and a run on a skewed simulated log."""

import math
from dataclasses import replace

import numpy as np
import pytest
from _log_fixtures import ROS_WRITERS, make_scans, split, write_log
from _run_helpers import run_cli

from cornerslam_cli.geometry import compose
from cornerslam_cli.logs import open_log
from cornerslam_cli.logs.base import ReadStats, make_scan
from cornerslam_cli.logs.deskew import deskew, motion, velocity
from cornerslam_cli.logs.sync import SyncStats, synchronise
from cornerslam_cli.simulate import simulate_log
from cornerslam_cli.simworld import office_world, raycast
from cornerslam_cli.types import OdomSample, Scan


def exp_se2(twist, t: float) -> np.ndarray:
    """The SE(2) exponential in its textbook form (not deskew.motion's): the pose after t seconds."""
    vx, vy, w = twist
    if abs(w) < 1e-12:
        return np.array([vx * t, vy * t, 0.0])
    th = w * t
    return np.array(
        [
            (vx * math.sin(th) - vy * (1 - math.cos(th))) / w,
            (vx * (1 - math.cos(th)) + vy * math.sin(th)) / w,
            th,
        ]
    )


@pytest.mark.parametrize("twist", [(0.5, 0.0, 0.0), (0.0, 0.0, 1.5), (0.7, -0.2, 1.2), (0.3, 0.1, -40.0)])
def test_motion_is_the_se2_exponential(twist):
    t = np.linspace(-0.1, 0.1, 21)
    assert motion(np.array(twist), t) == pytest.approx(np.array([exp_se2(twist, ti) for ti in t]), abs=1e-12)


@pytest.mark.parametrize("twist", [(0.5, 0.0, 0.0), (0.7, -0.2, 1.2), (0.3, 0.1, -4.0)])
def test_velocity_is_the_inverse_of_motion(twist):
    assert velocity(motion(np.array(twist), np.array([0.1]))[0], 0.1) == pytest.approx(twist, abs=1e-12)


def test_motion_agrees_with_integrating_small_steps():
    twist, step = np.array([0.8, 0.1, 2.0]), 1e-5
    pose = np.zeros(3)
    for _ in range(10_000):  # 0.1 s
        pose = compose(pose, exp_se2(twist, step))  # each step's own pose, composed
    assert motion(twist, np.array([0.1]))[0] == pytest.approx(pose, abs=1e-9)


def skewed_scan(twist, time_increment, laser2base, beams=541, fov=4 * math.pi / 3):
    """A scan of the office ray-cast beam by beam while the robot moves at ``twist`` from the base pose
    (2, 3, 0.4) at the stamp, and each beam's true end point in the laser's frame at the stamp."""
    world, base0 = office_world(), np.array([2.0, 3.0, 0.4])
    angles = -fov / 2 + fov / (beams - 1) * np.arange(beams)
    t = time_increment * np.arange(beams)
    base = np.array([compose(base0, exp_se2(twist, ti)) for ti in t])
    laser = compose(base, np.broadcast_to(laser2base, base.shape))
    r = raycast(world, laser, angles, 30.0)
    ok = np.isfinite(r)
    hit = laser[ok, :2] + r[ok, None] * np.column_stack(
        (np.cos(laser[ok, 2] + angles[ok]), np.sin(laser[ok, 2] + angles[ok]))
    )
    laser0 = compose(base0, laser2base)
    c, s = math.cos(laser0[2]), math.sin(laser0[2])
    d = hit - laser0[:2]
    truth = np.column_stack((c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]))
    idx = np.flatnonzero(ok)
    scan = Scan(
        0.0, r[ok], angles[ok], idx, beams, 0.0, 30.0, fov / (beams - 1), time_increment=time_increment
    )
    return scan, truth


@pytest.mark.parametrize("laser2base", [(0.0, 0.0, 0.0), (0.145, 0.05, 0.3)])
@pytest.mark.parametrize("twist", [(0.5, 0.0, 1.0), (0.3, 0.2, -2.0)])
def test_deskewed_beams_land_where_the_laser_saw_them_at_the_stamp(twist, laser2base):
    """A URG-04LX-like sweep (67 ms for 240°): turning at 1-2 rad/s moves far beams by decimetres;
    corrected with the true velocity, every beam is where the laser at the stamp would have seen it."""
    twist, dt = np.array(twist), 0.1 / 1024
    scan, truth = skewed_scan(twist, dt, laser2base)
    before = np.hypot(*(scan.points() - truth).T)
    after = np.hypot(*(deskew(scan, twist, dt, laser2base).points() - truth).T)
    assert before.max() > 0.05  # the skew is real
    assert after.max() < 1e-9
    out = deskew(scan, twist, dt, laser2base)
    assert np.all(np.diff(out.angles) > 0)  # beams keep their order
    assert (out.beam_index == scan.beam_index).all() and out.stamp == scan.stamp


def test_nothing_to_correct_returns_the_scan_itself():
    scan, _ = skewed_scan(np.zeros(3), 1e-4, (0.0, 0.0, 0.0))
    assert deskew(scan, np.zeros(3), 1e-4, (0.1, 0.0, 0.0)) is scan
    assert deskew(scan, np.array([0.5, 0.0, 1.0]), 0.0, (0.1, 0.0, 0.0)) is scan


def test_a_360_degree_laser_keeps_its_bearings_unwrapped():
    angles = np.linspace(0.0, 2 * np.pi, 720, endpoint=False)
    scan = Scan(0.0, np.full(720, 3.0), angles, np.arange(720), 720, 0.0, 30.0, angles[1])
    out = deskew(scan, np.array([0.2, 0.0, 1.0]), 1e-4, (0.0, 0.0, 0.0))
    assert np.all(np.diff(out.angles) > 0) and out.angles[-1] > np.pi
    assert np.abs(out.angles - angles).max() < 0.1


def test_synchronise_gives_the_velocity_after_the_stamp():
    """The twist is that of the two samples around the stamp — for a scan stamped exactly on a sample,
    that sample and the next (the sweep runs after the stamp); the last scan, on the last sample, is
    still synchronised, with no velocity to give."""
    msgs = [
        OdomSample(0.0, 0.0, 0.0, 0.0),
        OdomSample(1.0, 1.0, 0.0, 0.0),  # 1 m/s ahead
        scan_at(1.0),
        scan_at(1.5),
        OdomSample(2.0, 1.0, 0.0, 0.5),  # then a turn in place at 0.5 rad/s
        scan_at(2.0),
    ]
    out = list(synchronise(msgs))
    assert [s.scan.stamp for s in out] == [1.0, 1.5, 2.0]
    assert out[0].twist == pytest.approx([0.0, 0.0, 0.5]) and out[1].twist == pytest.approx([0.0, 0.0, 0.5])
    assert out[0].odom == pytest.approx([1.0, 0.0, 0.0])
    assert out[2].twist == pytest.approx([0.0, 0.0, 0.0]) and out[2].odom == pytest.approx([1.0, 0.0, 0.5])


def test_a_unicycle_arc_gives_its_own_velocity():
    """0.5 m/s forward while turning at 1 rad/s, sampled at 10 Hz: the chord between two samples points
    sideways of the robot's heading, the SE(2) logarithm of their relative pose does not."""
    tw = np.array([0.5, 0.0, 1.0])
    t = np.array([0.3, 0.4, 0.5, 0.6])
    odom = [OdomSample(ti, *p) for ti, p in zip(t, motion(tw, t), strict=True)]
    (s,) = synchronise([*odom[:2], scan_at(0.4), *odom[2:]])
    assert s.twist == pytest.approx(tw, abs=1e-9)


def test_the_velocity_is_the_mean_over_the_window_after_the_stamp():
    """Odometry at 50 Hz, every other sample 4 mm ahead (noise): the velocity is the mean over 0.1 s
    after the stamp, 0.04 m/s off where one 20 ms step would be 0.2 m/s off."""
    t = 0.02 * np.arange(20)
    x = 0.5 * t + np.where(np.arange(20) % 2, 0.004, 0.0)
    odom = [OdomSample(ti, xi, 0.0, 0.0) for ti, xi in zip(t, x, strict=True)]
    (s,) = synchronise([*odom[:5], scan_at(t[4]), *odom[5:]])
    assert s.twist == pytest.approx([0.54, 0.0, 0.0])  # from sample 4 (on time) to sample 9 (ahead)


def test_no_velocity_across_a_gap_of_the_odometry():
    msgs = [OdomSample(5.0, 0.0, 0.0, 0.0), scan_at(5.0), OdomSample(45.0, 40.0, 0.0, 3.0)]
    (s,) = synchronise(msgs)
    assert s.odom == pytest.approx([0.0, 0.0, 0.0]) and s.twist == pytest.approx([0.0, 0.0, 0.0])


def test_a_scan_on_the_last_sample_is_kept_when_later_scans_push_it_out():
    """The odometry stops at 10 s with a scan on its last sample, then scans go on: the scan cannot wait
    for a sample after it among the scans still kept (MAX_PENDING), so it is synchronised as it is."""
    msgs = [OdomSample(9.9, 0.0, 0.0, 0.0), OdomSample(10.0, 0.1, 0.0, 0.0), scan_at(10.0)]
    msgs += [scan_at(10.0 + 0.01 * i) for i in range(1, 1200)]
    st = SyncStats()
    out = list(synchronise(msgs, st))
    assert [s.scan.stamp for s in out] == [10.0] and st.scans_out == 1 and st.after_last_odom == 1199


def scan_at(t):
    return Scan(t, np.ones(3), np.array([-0.1, 0.0, 0.1]), np.arange(3), 3, 0.1, 10.0, 0.1)


def test_the_velocity_is_in_the_robot_frame():
    msgs = [OdomSample(0.0, 0.0, 0.0, np.pi / 2), scan_at(0.5), OdomSample(1.0, 0.0, 2.0, np.pi / 2)]
    (s,) = synchronise(msgs)
    assert s.twist == pytest.approx([2.0, 0.0, 0.0])  # 2 m/s along +y of the map is straight ahead


@pytest.mark.parametrize("fmt", sorted(ROS_WRITERS))
def test_time_increment_is_read_from_every_ros_format(fmt, tmp_path):
    path = write_log(fmt, tmp_path, scans=make_scans(time_increment=1e-4))
    with open_log(path) as log:
        scans, _ = split(log.messages())
    assert scans and all(s.time_increment == pytest.approx(1e-4, rel=1e-6) for s in scans)


def test_carmen_has_no_beam_times(tmp_path):
    with open_log(write_log("carmen", tmp_path, scans=make_scans(time_increment=1e-4))) as log:
        scans, _ = split(log.messages())
    assert scans and all(s.time_increment == 0.0 for s in scans)


LONG = "its 181 beams would take longer than 1 s"


@pytest.mark.parametrize(
    "bad, why",
    [
        (0.01, LONG),
        (-0.01, LONG),
        (float("nan"), "not a finite number"),
        (float("inf"), "not a finite number"),
    ],
)
def test_an_impossible_time_increment_is_warned_about_and_ignored(bad, why):
    """181 beams 10 ms apart would take 1.8 s: not a laser's sweep; the scan is kept, its beam times
    taken as not given. A NaN or inf is said to be no number (a probe: NaN's beams "would take longer
    than 1 s"), and the warning says input.beam_time then gives the times (it said "not corrected")."""
    st = ReadStats()
    for _ in range(2):
        scan = make_scan(st, "log", 1.0, -1.5, None, 1 / 60, 0.0, 30.0, np.ones(181), "laser", bad)
        assert scan is not None and scan.time_increment == 0.0
    assert st.bad_time_increment == 2
    assert [w for w in st.warnings if "time_increment" in w] == [
        f"log: scan at 1.000 has time_increment {bad!r} s ({why}): taken as not given, the beams' times "
        "from input.beam_time when set, else the scan is not corrected for motion"
    ]


def test_the_front_end_deskews_with_the_mount_and_the_log_s_own_beam_times_first():
    """frontend._deskewed: each scan by its own time_increment, else input.beam_time; at the laser's
    mount; where the times came from noted for summary.json."""
    from types import SimpleNamespace

    from cornerslam_cli.config import load_config
    from cornerslam_cli.frontend import _deskewed
    from cornerslam_cli.logs.sync import Synced

    mount, tw = (0.145, 0.05, 0.3), np.array([0.5, 0.0, 1.0])
    own, _ = skewed_scan(tw, 2e-4, mount)
    bare = replace(own, time_increment=0.0)
    pairs = [Synced(own, np.zeros(3), twist=tw), Synced(bare, np.zeros(3), twist=tw)]
    src = SimpleNamespace(laser2base=mount, beam_times="", beam_time=0.0)
    got = list(_deskewed(iter(pairs), src, load_config(None, ["input.beam_time=1e-4"])))
    assert got[0].scan.ranges == pytest.approx(deskew(own, tw, 2e-4, mount).ranges, abs=1e-12)
    assert got[1].scan.ranges == pytest.approx(deskew(bare, tw, 1e-4, mount).ranges, abs=1e-12)
    assert (src.beam_times, src.beam_time) == ("log", 2e-4)
    src = SimpleNamespace(laser2base=mount, beam_times="", beam_time=0.0)
    got = list(_deskewed(iter(pairs[1:]), src, load_config(None, ["input.beam_time=1e-4"])))
    assert (src.beam_times, src.beam_time) == ("config", 1e-4)
    src = SimpleNamespace(laser2base=mount, beam_times="", beam_time=0.0)
    assert list(_deskewed(iter(pairs), src, load_config(None, ["input.deskew=false"])))[0].scan is own
    assert src.beam_times == "off"


def test_a_skewed_simulated_log_is_straightened(tmp_path):
    """A log whose laser sweeps for 75 ms (a 10 Hz scanner's 270°) while the robot drives the office:
    deskewed (the default), the heading error between consecutive keyframes is half what it is with
    ``input.deskew=false``, near the same log's without skew (seeds 4-7: 0.0010-0.0011 rad against
    0.0020-0.0022, without skew 0.0006-0.0009; the rest of the gap is the simulated odometry's noise in
    the velocity). Not the ATE over the lap: it moves both ways with which keyframes the matcher gets
    wrong."""
    common = dict(seed=5, rate=5.0, beams=361)
    simulate_log(tmp_path / "skew.mcap", sweep=0.075, **common)
    on = run_cli(tmp_path / "skew.mcap", tmp_path / "on", "input.deskew=true")
    off = run_cli(tmp_path / "skew.mcap", tmp_path / "off", "input.deskew=false")
    simulate_log(tmp_path / "still.mcap", **common)
    still = run_cli(tmp_path / "still.mcap", tmp_path / "still")
    rot = [s["accuracy"]["rpe_step_rot_rmse"] for s in (on, off, still)]
    assert rot[0] < 0.7 * rot[1] and rot[0] < 2.0 * rot[2], rot
    assert [s["input"]["beam_times"] for s in (on, off, still)] == ["log", "off", "none"]
    assert on["input"]["beam_time"] == pytest.approx(0.075 / 360)
