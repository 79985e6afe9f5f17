"""A corpus of damaged and awkward logs, generated (never committed), each with its expected behaviour.

``build_corpus(dir)`` writes every entry into ``dir`` and returns ``{name: (path, Expected)}``; the
100,000-scan log is built only on request (``build_long_log``: benchmarks and slow tests). All
logs show one simulated robot circling a box in a 10 m × 8 m room (noise-free odometry, seeded
range noise), so every entry is the same small, valid run with one fault added:

* damaged files: truncated MCAP / ROS 1 bag at several cut points, an MCAP with a corrupt chunk;
* topics: the scan topic pointing at /odom, topics with no messages;
* scans: all-NaN / all-zero / negative / huge ranges, ranges count disagreeing with the angles,
  angle_increment 0 (in all scans, or in some) or negative (clockwise beams: processed);
* odometry: a jump and a reset to zero mid-log, NaN poses;
* stamps: scans and odometry out of order and repeated (MCAP, ROS 1 bag, CARMEN);
* reading (``_input_faults_ii``): JSON-encoded MCAP (foxglove_bridge / rosbridge), a topic in an
  encoding we do not decode, chunks not in time order, unnormalised and zero odometry quaternions,
  simulated time starting at stamp 0, tab-separated CARMEN, scans outside or far beyond the
  odometry, ``input.skip_beams_*`` removing every beam;
* ``_probe14_faults``: a ROS 2 bag whose metadata.yaml is not YAML; scan angles in degrees; an
  odometry sample 1e300 m away.

``python tests/fault_corpus.py DIR`` writes the corpus and prints what each entry expects.
"""

from __future__ import annotations

import math
import shutil
import struct
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from cornerslam_cli.logs.writers import RawScan, write_carmen, write_mcap, write_rosbag1, write_rosbag2
from cornerslam_cli.simworld import make_world, raycast, rectangle, room
from cornerslam_cli.types import OdomSample

T0 = 1_700_000_000.0
RATE = 10.0  # scans and odometry samples per second
N = 40  # scans of a corpus log (4 s)
WORLD = make_world([room(0.0, 0.0, 10.0, 8.0), rectangle(5.0, 4.0, 2.0, 1.5)], "fault-room")


@dataclass(frozen=True)
class Expected:
    """What ``cornerslam run LOG --out OUT *args`` must do.

    exit_code 0: processed; ``message`` fragments appear in a warning on stderr; ``counts`` are
    summary.json counts, an int (exact) or an inclusive (lo, hi) range.
    exit_code 2: refused; ``message`` fragments appear in the one-line error; no output directory.
    """

    behaviour: str  # one line for the docs table
    exit_code: int
    message: tuple[str, ...] = ()
    counts: dict[str, int | tuple[int, int]] = field(default_factory=dict)
    args: tuple[str, ...] = ()


# --------------------------------------------------------------------------- checks shared by the fault tests
def check_error_line(res, fragments) -> None:
    """Exit 2 and exactly one 'error:' line, the last on stderr, naming what it must; no traceback."""
    assert res.exit_code == 2, res.output
    lines = res.stderr.strip().splitlines()
    assert [ln for ln in lines if ln.startswith("error:")] == lines[-1:], res.stderr
    assert "Traceback" not in res.output
    for f in fragments:
        assert f in lines[-1], lines[-1]


def peak_bytes(run: Callable[[], object]) -> int:
    """Peak traced Python memory (bytes) while ``run()`` runs."""
    import tracemalloc

    tracemalloc.start()
    try:
        run()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


# --------------------------------------------------------------------------- the simulated robot
def truth(t: np.ndarray) -> np.ndarray:
    """(k, 3) true base poses at times t (seconds since T0): a circle of radius 2.8 m around the box."""
    w = 0.4 / 2.8  # 0.4 m/s
    a = w * t - math.pi / 2
    return np.column_stack((5.0 + 2.8 * np.cos(a), 4.0 + 2.8 * np.sin(a), a + math.pi / 2))


def scan_stamp(i: int) -> float:
    return T0 + (i + 0.5) / RATE  # halfway between two odometry samples


def make_scans(
    n: int = N, beams: int = 181, seed: int = 0, ranges: Callable[[int, np.ndarray], np.ndarray] | None = None
) -> Iterator[RawScan]:
    """n scans (270°, ``beams`` beams) ray cast in WORLD with 5 mm noise; ``ranges(i, r)`` edits scan i."""
    rng = np.random.default_rng(seed)
    inc = math.radians(270.0) / (beams - 1)
    angles = -math.radians(135.0) + inc * np.arange(beams)
    for i in range(n):
        t = scan_stamp(i)
        pose = truth(np.array([t - T0]))[0]
        r = raycast(WORLD, pose, angles, 30.0) + rng.normal(0.0, 0.005, beams)
        if ranges is not None:
            r = ranges(i, r)
        yield RawScan(t, -math.radians(135.0), inc, r, 0.05, 30.0, "laser")


def make_odoms(
    n: int = N + 1, edit: Callable[[int, np.ndarray], np.ndarray] | None = None
) -> list[OdomSample]:
    """n odometry samples at T0 + i / RATE (the true poses); ``edit(i, pose)`` changes sample i."""
    t = np.arange(n) / RATE
    out = []
    for i, p in enumerate(truth(t)):
        q = edit(i, p) if edit is not None else p
        out.append(OdomSample(T0 + t[i], float(q[0]), float(q[1]), float(q[2])))
    return out


def write_gt(path: Path, n: int = N) -> Path:
    """LOG.gt.tum beside the log: the true poses at the scan stamps (the run then reports ATE)."""
    from cornerslam_cli.report.tables import write_tum

    stamps = np.array([scan_stamp(i) for i in range(n)])
    write_tum(path.with_suffix(".gt.tum"), stamps, truth(stamps - T0))
    return path


# --------------------------------------------------------------------------- damage
def cut(src: Path, dst: Path, nbytes: int) -> Path:
    dst.write_bytes(src.read_bytes()[:nbytes])
    return dst


def mcap_records(data: bytes) -> Iterator[tuple[int, int, int]]:
    """(opcode, body_start, body_len) of the top-level records of an MCAP file."""
    off = 8
    while off + 9 <= len(data):
        op, n = struct.unpack_from("<BQ", data, off)
        yield op, off + 9, n
        off += 9 + n


def cut_before_first_scan(dst: Path) -> Path:
    """The valid log, uncompressed, cut right after its /scan channel record: the channel is known,
    none of its messages is in the file."""
    data = write_mcap(dst, make_scans(), make_odoms(), compression="none").read_bytes()
    topic = data.index(struct.pack("<I", 5) + b"/scan")  # the channel record's topic string
    (encoding,) = struct.unpack_from("<I", data, topic + 9)
    (metadata,) = struct.unpack_from("<I", data, topic + 13 + encoding)
    return cut(dst, dst, topic + 17 + encoding + metadata)


def corrupt_chunk(src: Path, dst: Path, which: int = 1) -> Path:
    """Copy of an MCAP with 64 bytes in the middle of its ``which``-th chunk zeroed."""
    data = bytearray(src.read_bytes())
    chunks = [(s, n) for op, s, n in mcap_records(bytes(data)) if op == 0x06]
    start, n = chunks[which]
    mid = start + n // 2
    data[mid : mid + 64] = bytes(64)
    dst.write_bytes(bytes(data))
    return dst


class _MismatchScan(RawScan):
    """A scan whose angle_max claims 10 more beams than its ranges hold."""

    @property
    def angle_max(self) -> float:
        return self.angle_min + (len(self.ranges) + 9) * self.angle_increment


def _mismatched(scans):
    for s in scans:
        yield _MismatchScan(s.stamp, s.angle_min, s.angle_increment, s.ranges, s.range_min, s.range_max)


def _with_increment(scans, inc: float, every: int = 1):
    for i, s in enumerate(scans):
        yield replace(s, angle_increment=inc) if i % every == 0 else s


def _empty_topics_mcap(path: Path, with_odom: bool) -> Path:
    """An MCAP with /scan and /odom channels but no scan messages (and odometry if ``with_odom``)."""
    from mcap.writer import Writer

    from cornerslam_cli.logs.writers import LASERSCAN, ODOMETRY, RosSerializer

    ros = RosSerializer("cdr")
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="fault_corpus")
        ids = {}
        for topic, typ in (("/scan", LASERSCAN), ("/odom", ODOMETRY)):
            sid = w.register_schema(name=typ, encoding="ros2msg", data=ros.msgdef(typ).encode())
            ids[topic] = w.register_channel(topic=topic, message_encoding="cdr", schema_id=sid)
        if with_odom:
            for o in make_odoms():
                t = int(round(o.stamp * 1e9))
                w.add_message(ids["/odom"], t, ros.odometry(o, "odom", "base_link"), t)
        w.finish()
    return path


def _shuffled_stamps(scans: list[RawScan], odoms: list[OdomSample]):
    """Scans 10 and 20 repeat the previous stamp, scan 30 goes back 0.25 s; odometry 15 repeats 14's.

    The writers merge their (assumed sorted) inputs lazily, so the file keeps this disorder."""
    out = []
    for i, s in enumerate(scans):
        if i in (10, 20):
            s = replace(s, stamp=scan_stamp(i - 1))
        elif i == 30:
            s = replace(s, stamp=scan_stamp(i) - 0.25)
        out.append(s)
    odo = [replace(o, stamp=odoms[14].stamp) if i == 15 else o for i, o in enumerate(odoms)]
    return out, odo


# --------------------------------------------------------------------------- the corpus
VALID_COUNTS = {"steps": N, "scans_in": N, "scans_skipped": 0, "odom_jumps": 0, "messages_failed": 0}
TRUNCATED = "no end magic/footer"


def build_corpus(d: str | Path) -> dict[str, tuple[Path, Expected]]:
    """Write every corpus log into ``d``; ``{name: (path, expected)}``."""
    d = Path(d)
    d.mkdir(parents=True, exist_ok=True)
    out: dict[str, tuple[Path, Expected]] = {}

    def add(name: str, path: Path, exp: Expected) -> None:
        out[name] = (path, exp)

    # -- the valid log, in small chunks so that damage hits one chunk of several
    good = write_gt(write_mcap(d / "good.mcap", make_scans(), make_odoms(), chunk_size=16 * 1024))
    add("valid", good, Expected("processed", 0, counts=VALID_COUNTS))

    # -- damaged files
    size = good.stat().st_size
    cut_short = "the recorder stopped early", "record again, or give the complete file"
    add(
        "mcap_cut_in_header",
        cut(good, d / "cut_header.mcap", 40),
        Expected(
            "exit 2: truncated, no LaserScan topic before the cut",
            2,
            ("'cut_header.mcap' is truncated: no sensor_msgs/LaserScan topic before the cut", *cut_short),
        ),
    )
    first_chunk = next((s, n) for op, s, n in mcap_records(good.read_bytes()) if op == 0x06)
    add(
        "mcap_cut_in_first_chunk",
        cut(good, d / "cut_first_chunk.mcap", first_chunk[0] + first_chunk[1] // 2),
        Expected(
            "exit 2: truncated, no LaserScan topic before the cut",
            2,
            (
                "'cut_first_chunk.mcap' is truncated: no sensor_msgs/LaserScan topic before the cut",
                *cut_short,
            ),
        ),
    )
    add(
        "mcap_cut_before_first_scan",
        cut_before_first_scan(d / "cut_before_scan.mcap"),
        Expected(
            "exit 2: truncated, no scan message before the cut",
            2,
            ("'cut_before_scan.mcap' is truncated: no message of topic '/scan' before the cut", *cut_short),
        ),
    )
    add(
        "mcap_cut_with_a_mistyped_scan_topic",
        cut(good, d / "cut_typo.mcap", size * 9 // 10),
        Expected(
            "exit 2: no such topic, the file's LaserScan topics listed (a typo is as likely as the cut)",
            2,
            (
                "has no topic '/scna' before the cut (the file is truncated) (LaserScan topics: /scan)",
                "check --scan-topic",
            ),
            args=("--scan-topic", "/scna"),
        ),
    )
    for pct in (30, 60, 90):
        add(
            f"mcap_cut_{pct}pct",
            cut(good, d / f"cut_{pct}.mcap", size * pct // 100),
            Expected(
                "processed up to the last complete chunk, warned",
                0,
                (TRUNCATED, "messages after the cut are lost"),
                {"steps": (N * pct // 100 - 12, N * pct // 100), "scans_skipped": (0, 1)},
            ),
        )
    add(
        "mcap_cut_in_footer",
        cut(good, d / "cut_footer.mcap", size - 4),
        Expected("every scan processed (index rebuilt by a scan), warned", 0, (TRUNCATED,), VALID_COUNTS),
    )
    add(
        "mcap_corrupt_chunk",
        corrupt_chunk(good, d / "corrupt_chunk.mcap"),
        Expected(
            "the corrupt chunk skipped, warned", 0, ("does not decompress",), {"steps": (N // 2, N - 5)}
        ),
    )
    bag = write_rosbag1(d / "good.bag", make_scans(), make_odoms())
    bag_size = bag.stat().st_size
    for pct in (10, 50, 95):
        add(
            f"bag_cut_{pct}pct",
            cut(bag, d / f"cut_{pct}.bag", bag_size * pct // 100),
            Expected(
                "exit 2: the bag's index is gone; run `rosbag reindex`", 2, (f"cut_{pct}.bag", "reindex")
            ),
        )

    # -- topics
    add(
        "scan_topic_is_odometry",
        good,
        Expected(
            "exit 2: names the topic's type and the LaserScan topics",
            2,
            ("'/odom'", "nav_msgs/Odometry, not sensor_msgs/LaserScan", "--scan-topic"),
            args=("--scan-topic", "/odom"),
        ),
    )
    for name, with_odom in (("empty_topics", False), ("empty_scan_topic", True)):
        add(
            name,
            _empty_topics_mcap(d / f"{name}.mcap", with_odom),
            Expected("exit 2: the topic has no messages", 2, (f"{name}.mcap", "has no messages")),
        )

    # -- ranges
    for name, value in (("nan", np.nan), ("zero", 0.0), ("negative", -1.0), ("huge", 1e30)):
        scans = make_scans(ranges=lambda i, r, v=value: np.full_like(r, v))
        add(
            f"ranges_all_{name}",
            write_mcap(d / f"ranges_{name}.mcap", scans, make_odoms()),
            Expected(
                "exit 2: every beam is invalid",
                2,
                (f"ranges_{name}.mcap", "every beam of every scan is invalid"),
            ),
        )
    far = make_scans(ranges=lambda i, r: np.where(np.arange(len(r)) % 3 == 0, 1e30, r))
    add(
        "ranges_huge_without_range_max",
        write_mcap(d / "ranges_far.mcap", (replace(s, range_max=math.inf) for s in far), make_odoms()),
        Expected("processed; beams at 1e30 m are far points that fit no line", 0, counts=VALID_COUNTS),
    )
    add(
        "ranges_nan_in_some_scans",
        write_mcap(
            d / "ranges_some_nan.mcap",
            make_scans(ranges=lambda i, r: np.full_like(r, np.nan) if i % 4 == 0 else r),
            make_odoms(),
        ),
        Expected(
            "processed; blind scans only predict, invalid beams counted",
            0,
            counts={"steps": N, "beams_total": N * 181, "beams_invalid": (N // 4) * 181},
        ),
    )
    add(
        "ranges_count_mismatch",
        write_mcap(d / "mismatch.mcap", _mismatched(make_scans()), make_odoms()),
        Expected(
            "processed with len(ranges) beams from angle_min, counted, warned",
            0,
            ("imply",),
            {"steps": N, "scans_size_mismatch": N},
        ),
    )
    add(
        "angle_increment_zero",
        write_mcap(d / "inc_zero.mcap", _with_increment(make_scans(), 0.0), make_odoms()),
        Expected(
            "exit 2: every scan has a bad angle_increment",
            2,
            ("inc_zero.mcap", f"all {N} scans on '/scan' were skipped", "angle_increment"),
        ),
    )
    add(
        "angle_increment_negative",
        write_mcap(d / "inc_negative.mcap", _with_increment(make_scans(), -math.radians(1.5)), make_odoms()),
        Expected(
            "processed: beams clockwise, read in increasing bearing order",
            0,
            counts={"steps": N, "scans_bad_geometry": 0},
        ),
    )
    add(
        "angle_increment_zero_in_some_scans",
        write_mcap(d / "inc_some_zero.mcap", _with_increment(make_scans(), 0.0, every=5), make_odoms()),
        Expected(
            "processed; bad scans skipped, counted, warned",
            0,
            ("angle_increment",),
            {"steps": N - N // 5, "scans_bad_geometry": N // 5},
        ),
    )

    # -- odometry: a jump, a reset to zero, NaN poses
    def jump(i, p):
        return p + np.array([5.0, -3.0, 0.0]) if i >= 20 else p

    def reset(i, p):
        return p - truth(np.array([2.0]))[0] if i >= 20 else p  # (0, 0, 0) at t = 2 s

    for name, edit in (("jump", jump), ("reset", reset)):
        add(
            f"odom_{name}",
            write_gt(write_mcap(d / f"odom_{name}.mcap", make_scans(), make_odoms(edit=edit))),
            Expected(
                "processed; the jump is not applied as motion (odometry re-anchored; scan matching "
                "finds the motion, or without it the robot uncertainty is inflated), counted, warned",
                0,
                ("odometry jumped",),
                dict(VALID_COUNTS, odom_jumps=1),
            ),
        )

    def nan_pose(i, p):
        return np.full(3, np.nan) if i in (12, 13) else p

    for fmt, writer, suffix in (("mcap", write_mcap, ".mcap"), ("carmen", write_carmen, ".clf")):
        add(
            f"odom_nan_{fmt}",
            writer(d / f"odom_nan{suffix}", make_scans(), make_odoms(edit=nan_pose)),
            Expected(
                "processed; non-finite odometry samples skipped, counted, warned",
                0,
                ("non-finite pose",),
                dict(VALID_COUNTS, messages_failed=2),
            ),
        )

    # -- stamps out of order and repeated, in three formats. The MCAP and bag readers deliver
    # messages in log-time order, and the CARMEN log's scan 0.25 s back is put back in order
    # (order.in_stamp_order), so only the repeated stamps are skipped.
    for fmt, writer, suffix, late in (
        ("mcap", write_mcap, ".mcap", 2),
        ("bag", write_rosbag1, ".bag", 2),
        ("carmen", write_carmen, ".clf", 2),
    ):
        scans, odoms = _shuffled_stamps(list(make_scans()), make_odoms())
        add(
            f"stamps_disordered_{fmt}",
            writer(d / f"stamps{suffix}", scans, odoms),
            Expected(
                "processed; late and repeated messages skipped, counted, warned",
                0,
                ("went backwards",),
                {"steps": N - late, "scan_time_backwards": late, "odom_time_backwards": 1},
            ),
        )
    _config_faults(d, add)
    _ground_truth_faults(d, add)
    _input_faults_ii(d, add)
    _probe2_faults(d, add)
    _probe14_faults(d, add)
    return out


# --------------------------------------------------------------------------- config files and --set
def alias_bomb(levels: int = 9, width: int = 9) -> str:
    """YAML whose last anchor expands to width**levels scalars ("billion laughs": 9⁹ = 387 million),
    used as the value of a real key (so an error message that printed the value would expand it)."""
    lines = [f"a0: &a0 [{', '.join(['lol'] * width)}]"]
    for i in range(1, levels):
        lines.append(f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * width)}]")
    return "\n".join(lines) + f"\nekf:\n  alpha1: *a{levels - 1}\n"


def _write(d: Path, name: str, content: str | bytes) -> Path:
    path = d / name
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    return path


def _config_faults(d: Path, add: Callable[[str, Path, Expected], None]) -> None:
    """The valid log with a bad config file or --set: exit 2 naming the file (and line) or the dotted
    key and the allowed range, before the log is read; and the awkward configs that are fine."""
    good = d / "good.mcap"
    (d / "config_dir.yaml").mkdir(exist_ok=True)
    not_text, bad = "exit 2: the file is not UTF-8 text", "exit 2 naming the file or key"
    files = [  # name, content, behaviour, fragments of the error line
        ("not_utf8", b"ekf:\n  alpha1: 0.05  # caf\xe9\n", not_text, ("not UTF-8 text", "0xe9 at line 2")),
        ("utf16", "ekf:\n  alpha1: 0.05\n".encode("utf-16"), not_text, ("is UTF-16 text",)),
        ("binary", bytes(range(256)) * 4, not_text, ("binary file",)),
        ("alias_bomb", alias_bomb(), "exit 2: expands past 10,000 nodes", ("expands to more than 10,000",)),
        ("recursive_alias", "ekf: &e\n  alpha1: *e\n", bad, ("alias inside its own anchor",)),
        ("nested_too_deep", "ekf:\n  a: " + "[" * 2000 + "]" * 2000, bad, ("nested too deeply",)),
        ("too_large", "#" * (1 << 20) + "\n", "exit 2: larger than 1 MiB", ("larger than 1024 KiB",)),
        ("a_list", "- ekf\n- lines\n", bad, ("must contain a mapping of sections, not list",)),
        ("a_scalar", "3\n", bad, ("must contain a mapping of sections, not int",)),
        ("section_scalar", "ekf: 3\n", bad, ("section 'ekf' must be a mapping of its keys, got 3",)),
        ("control_char", "ekf:\n  alpha1: 0.05\n  alpha2: \x07\n", bad, ("line 3", "control character #x07")),
        ("two_documents", "ekf: {}\n---\nekf: {}\n", bad, ("line 2", "expected a single document")),
        ("duplicated_key", "ekf:\n  alpha1: 0.1\n  alpha1: 0.2\n", bad, ("line 3", "is given twice")),
        ("number_as_key", "1: 2\n", bad, ("unknown config key '1'",)),
        ("base_60", "keyframes:\n  max_interval: 1:30\n", bad,
         ("line 2", "'keyframes.max_interval' = 1:30 is a base-60 number to YAML 1.1, read as 90")),
        ("bool_as_1", "ekf:\n  fuse: 1\n", bad, ("'ekf.fuse' must be true or false, got 1",)),
        ("nan", "input:\n  laser:\n    x: .nan\n", bad, ("'input.laser.x' = nan is not a finite number",)),
        ("inf", "keyframes:\n  linear_update: .inf\n", bad, ("'keyframes.linear_update' = inf",)),
        ("degrees", "input:\n  laser:\n    yaw: 90\n", bad, ("'input.laser.yaw' = 90.0 is out of range",)),
        ("5000_digits", "ekf:\n  alpha2: 1" + "0" * 5000 + "\n", bad,
         ("'ekf.alpha2' = 1000", "(5,001 digits) is out of range", "allowed: [0, 100]")),
    ]  # fmt: skip
    for name, content, behaviour, message in files:
        path = _write(d, f"config_{name}.yaml", content)
        add(f"config_{name}", good, Expected(behaviour, 2, message, args=("--config", path)))
    directory = d / "config_dir.yaml"
    add("config_directory", good, Expected(bad, 2, ("is a directory",), args=("--config", directory)))
    sets = [  # name, --set KEY=VALUE, fragments of the error line
        ("nan", "ekf.alpha1=nan", ("'ekf.alpha1' = nan is not a finite number", "allowed: [0, 100]")),
        ("inf", "scan_match.voxel=inf", ("'scan_match.voxel' = inf is not a finite number",)),
        ("yaml_minus_inf", "corners.d_min=-.inf", ("'corners.d_min' = -inf",)),
        ("1e999", "sensor.sigma_theta=1e999", ("'sensor.sigma_theta' = inf",)),
        ("400_digits", "ekf.alpha2=1" + "0" * 400, ("'ekf.alpha2' = inf",)),
        ("5000_digits", "ekf.initial_capacity=-1" + "0" * 5000,
         ("'ekf.initial_capacity' = -1000", "(5,001 digits) is out of range", "[1, 1000]")),
        ("5000_hex_digits", "ekf.alpha1=0x" + "f" * 5000,  # int() converts it, no message could print it
         ("'ekf.alpha1' = 0xffffffff... (5,000 digits) is out of range", "[0, 100]")),
        ("20000_binary_digits_as_topic", "input.scan_topic=0b" + "1" * 20000,
         ("'input.scan_topic' must be a string, got 0b11111111... (20,000 digits)",)),
        ("capacity", "ekf.initial_capacity=10000000000", ("'ekf.initial_capacity' = 1000000", "[1, 1000]")),
        ("sigma_1e300", "sensor.sigma_r_near=1e300", ("'sensor.sigma_r_near' = 1e+300 is out of range",)),
        ("group_size", "association.pca.group_size=1000000", ("'association.pca.group_size'", "[1, 1000]")),
        ("adapt_samples", "scan_match.adapt_min_samples=1000", ("adapt_min_samples = 1000 exceeds",)),
        ("search_window", "scan_match.search_max_xy=100", ("'scan_match.search_max_xy' = 100", "(0, 5]")),
        ("on_as_string", "input.odom_frame=on", ("'input.odom_frame' must be a string, got True", "quote")),
        ("unknown_laser_preset", "input.laser_preset=x",
         ("config key 'input.laser_preset' = 'x' is not a laser preset", "choices: auto, none")),
        ("base_60", "keyframes.max_interval=1:30", ("'keyframes.max_interval' = 1:30 is a base-60 number",)),
        ("no_equals", "ekf.alpha1", ("is not key=value",)),
        ("empty_key", "=0.1", ("has an empty key",)),
        ("empty_key_part", "association..alpha=0.1", ("has an empty key",)),
    ]  # fmt: skip
    for name, text, message in sets:
        add(f"set_{name}", good, Expected(f"--set {text[:40]}: exit 2", 2, message, args=("--set", text)))
    fine = [  # processed with the defaults: an empty config, YAML 1.1 booleans (yes/off), an alias,
        # sections left empty (every key commented out: YAML reads null)
        ("config_dev_null", Path("/dev/null")),
        (
            "config_empty_sections",
            _write(d, "config_empty.yaml", "ekf:\n#  alpha1: 0.1\nassociation:\n  jcbb:\n"),
        ),
        ("config_yes_off", _write(d, "config_yes.yaml", "ekf:\n  fuse: yes\n  joseph: off\n")),
        ("config_alias", _write(d, "config_alias.yaml", "ekf:\n  alpha1: &a 0.05\n  alpha3: *a\n")),
    ]
    for name, path in fine:
        add(name, good, Expected("processed", 0, counts=VALID_COUNTS, args=("--config", path)))


# --------------------------------------------------------------------------- ground truth and relations
def _ground_truth_faults(d: Path, add: Callable[[str, Path, Expected], None]) -> None:
    """The valid log with a damaged --ground-truth or --relations file: refused before the run (exit 2
    naming the file), or processed with a warning (the ground truth sorted; no accuracy when it does
    not overlap the run, rather than NaN in summary.json)."""
    good = d / "good.mcap"
    rows = good.with_suffix(".gt.tum").read_text().splitlines()
    swapped = list(rows)
    swapped[3], swapped[30] = swapped[30], swapped[3]
    shifted = [" ".join([f"{float(r.split()[0]) + 1000.0:.9f}", *r.split()[1:]]) for r in rows]
    conflict = [*rows[:5], rows[5].replace(" 0 0 0 ", " 0 0 0.5 ", 1), *rows[5:]]
    repeated = [*rows[:10], rows[9], rows[9], *rows[10:]]
    with_nan = [*rows[:7], "nan 1 2 0 0 0 0 1", *rows[7:]]
    latin1 = "# café\n".encode("latin-1") + "\n".join(rows).encode()
    stamps = [r.split()[0] for r in rows]
    relations = [f"{a} {b} 0.1 0.02 0 0 0 0.05" for a, b in zip(stamps[:-1], stamps[1:], strict=True)]
    positions = [" ".join([*r.split()[:4], "0 0 0 0"]) for r in rows]  # no orientation: not a relation
    w_first = [" ".join([*r.split()[:4], r.split()[7], *r.split()[4:7]]) for r in rows]  # qw qx qy qz
    log = good.read_bytes()
    no, ok, warned = "exit 2 naming the file", 0, "processed, warned"
    gt, rel = "--ground-truth", "--relations"
    entries = [  # option, name, content, exit code, behaviour, fragments of the error or warning
        (gt, "gt_unsorted", "\n".join(swapped), ok, "sorted by stamp, warned", ("not in time order",)),
        (gt, "gt_repeated", "\n".join(repeated), ok, "repeats dropped, warned", ("repeats 2 line(s)",)),
        (gt, "gt_no_overlap", "\n".join(shifted), ok, "no ATE/RPE (accuracy null), warned",
         ("does not overlap the trajectory", "no ATE/RPE")),
        (gt, "gt_first_half", "\n".join(rows[: len(rows) // 2]), ok, "ATE/RPE over what it covers, warned",
         ("covers", "of the run's", "ATE/RPE are over those")),
        (gt, "gt_two_poses_one_stamp", "\n".join(conflict), 2, no, ("two different poses", "lines 6 and 7")),
        (gt, "gt_nan", "\n".join(with_nan), 2, no, ("line 8", "not finite")),
        (gt, "gt_random_bytes", np.random.default_rng(1).bytes(4000), 2, no, ("binary file",)),
        (gt, "gt_utf16", "\n".join(rows).encode("utf-16"), 2, no, ("is UTF-16 text",)),
        (gt, "gt_latin1", latin1, 2, no, ("not UTF-8 text", "line 1")),
        (gt, "gt_is_a_log", log, 2, no, ("gt_is_a_log' is a binary file",)),
        (gt, "gt_is_relations", "\n".join(relations), 2, no, ("looks like a relations file", "--relations")),
        (gt, "gt_positions_only", "\n".join(positions), 2, no, ("line 1 has a zero-length quaternion",)),
        (gt, "gt_quaternion_w_first", "\n".join(w_first), 2, no, ("out of the plane", "with qw first?")),
        (rel, "relations_binary", log[:3000], 2, no, ("relations file", "binary")),
        (rel, "relations_header", "t1 t2 x y z roll pitch yaw\n", 2, no, ("line 1 is not a relation",)),
        (rel, "relations_outside", "1 2 0 0 0 0 0 0", ok, warned, ("no relation", "falls inside the run")),
        (rel, "relations_is_a_tum", "\n".join(rows), 2, no, ("looks like a TUM traj", "--ground-truth")),
    ]  # fmt: skip
    for option, name, content, code, behaviour, message in entries:
        path = _write(d, name, content)
        counts = VALID_COUNTS if code == 0 else {}
        add(name, good, Expected(behaviour, code, message, counts, args=(option, path)))


def _foreign_encoding_mcap(path: Path, topic: str) -> Path:
    """The valid log with ``topic`` recorded as protobuf under its ROS type name: ``/scan`` (instead
    of CDR) or ``/tf`` (an extra tf topic beside the CDR scans and odometry)."""
    from mcap.writer import Writer

    from cornerslam_cli.logs.writers import LASERSCAN, ODOMETRY, TFMESSAGE, RosSerializer

    ros = RosSerializer("cdr")
    proto = b"\x0a\x03abc"  # a protobuf message: field 1, 3 bytes
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="", library="fault_corpus")
        ids = {}
        for name, typ in (("/scan", LASERSCAN), ("/odom", ODOMETRY), ("/tf", TFMESSAGE)):
            if name == topic:
                sid = w.register_schema(name=typ, encoding="protobuf", data=b"\x0a\x00")
                ids[name] = w.register_channel(topic=name, message_encoding="protobuf", schema_id=sid)
            elif name != "/tf":
                sid = w.register_schema(name=typ, encoding="ros2msg", data=ros.msgdef(typ).encode())
                ids[name] = w.register_channel(topic=name, message_encoding="cdr", schema_id=sid)
        for m in sorted([*make_scans(), *make_odoms()], key=lambda m: m.stamp):
            t = int(round(m.stamp * 1e9))
            if isinstance(m, OdomSample):
                w.add_message(ids["/odom"], t, ros.odometry(m, "odom", "base_link"), t)
                if "/tf" in ids:
                    w.add_message(ids["/tf"], t, proto, t)
            else:
                w.add_message(ids["/scan"], t, proto if topic == "/scan" else ros.laserscan(m), t)
        w.finish()
    return path


def _sim_time(scans: Iterator[RawScan], odoms: list[OdomSample]):
    """The log in simulated time (Gazebo, use_sim_time): stamps from exactly 0.0 (scan i and odometry
    sample i at i / RATE); the writers add T0 for the log (wall-clock receive) time."""
    return (replace(s, stamp=i / RATE) for i, s in enumerate(scans)), [
        replace(o, stamp=i / RATE) for i, o in enumerate(odoms)
    ]


def _input_faults_ii(d: Path, add: Callable[[str, Path, Expected], None]) -> None:
    """Reading faults of issue 13: encodings, chunk order, quaternions, zero stamps, CARMEN tabs,
    scans without odometry, skipping every beam."""

    # -- JSON messages (foxglove_bridge / rosbridge recordings), NaN/inf ranges as null
    def holes(i, r):
        return np.where(np.arange(len(r)) % 10 == 0, np.inf if i % 2 else np.nan, r)

    for enc in ("json", "json-ros1"):
        add(
            f"mcap_{enc.replace('-', '_')}",
            write_mcap(
                d / f"{enc}.mcap", make_scans(ranges=holes), make_odoms(), encoding=enc, tf_static=(0.1, 0, 0)
            ),
            Expected(
                "processed: JSON decoded (ROS 2 or ROS 1 field names; null ranges are invalid beams)",
                0,
                counts=dict(VALID_COUNTS, beams_invalid=N * 19),
            ),
        )
    add(
        "mcap_scan_topic_protobuf",
        _foreign_encoding_mcap(d / "protobuf_scan.mcap", "/scan"),
        Expected(
            "exit 2: names the topic and its message encoding",
            2,
            ("protobuf_scan.mcap", "'/scan'", "message encoding 'protobuf'"),
        ),
    )
    add(
        "mcap_tf_topic_protobuf",
        _foreign_encoding_mcap(d / "protobuf_tf.mcap", "/tf"),
        Expected(
            "processed; the tf topic in protobuf is not read, warned", 0, ("'/tf'", "protobuf"), VALID_COUNTS
        ),
    )
    add(
        "mcap_chunks_unsorted",
        write_mcap(d / "unsorted_chunks.mcap", make_scans(), make_odoms(), shuffle_blocks=8),
        Expected("processed in log-time order (the chunk index gives the order)", 0, counts=VALID_COUNTS),
    )

    # -- odometry quaternions: twice unit length everywhere; of zero length in two samples
    def doubled(o):
        return (0.0, 0.0, 2 * math.sin(o.theta / 2), 2 * math.cos(o.theta / 2))

    def zero_in_two(o):
        return (
            (0.0,) * 4
            if round((o.stamp - T0) * RATE) in (12, 13)
            else (0.0, 0.0, math.sin(o.theta / 2), math.cos(o.theta / 2))
        )

    add(
        "odom_quaternion_doubled",
        write_gt(write_mcap(d / "quat_x2.mcap", make_scans(), make_odoms(), odom_quaternion=doubled)),
        Expected(
            "processed; quaternions normalised, warned", 0, ("not of unit length: normalised",), VALID_COUNTS
        ),
    )
    add(
        "odom_quaternion_zero",
        write_mcap(d / "quat_zero.mcap", make_scans(), make_odoms(), odom_quaternion=zero_in_two),
        Expected(
            "processed; samples with a zero-length quaternion skipped, counted, warned",
            0,
            ("zero-length orientation quaternion",),
            dict(VALID_COUNTS, messages_failed=2),
        ),
    )

    # -- simulated time: header stamps from exactly 0.0, log time from the wall clock
    for fmt, writer, suffix in (("mcap", write_mcap, ".mcap"), ("bag", write_rosbag1, ".bag")):
        scans, odoms = _sim_time(make_scans(), make_odoms())
        add(
            f"stamps_sim_time_from_zero_{fmt}",
            writer(d / f"sim_time{suffix}", scans, odoms, log_time_offset=T0),
            Expected("processed: 0.0 is a valid stamp", 0, counts=VALID_COUNTS),
        )

    # -- CARMEN separated by tabs
    add(
        "carmen_tabs",
        write_carmen(d / "tabs.clf", make_scans(), make_odoms(), sep="\t"),
        Expected("processed: fields separated by any whitespace", 0, counts=VALID_COUNTS),
    )

    # -- scans outside the odometry: the second half after its last sample; a wrong clock
    add(
        "odom_ends_halfway",
        write_mcap(d / "odom_half.mcap", make_scans(), make_odoms(N // 2 + 1)),
        Expected(
            "processed; scans after the last odometry sample skipped, counted, warned (in summary.json too)",
            0,
            ("after the last odometry sample",),
            {"steps": N // 2, "after_last_odom": N // 2, "scans_skipped": N // 2},
        ),
    )
    add(
        "odom_other_clock",
        write_mcap(
            d / "odom_clock.mcap", make_scans(), [replace(o, stamp=o.stamp - 1000.0) for o in make_odoms()]
        ),
        Expected(
            "exit 2: no scan within the odometry's time span; the counts say why",
            2,
            (
                "odom_clock.mcap",
                "no scan could be processed",
                f"{N} after the last odometry sample",
                "and the odometry",
                "s apart)",
            ),  # (the two spans, which do not overlap)
        ),
    )

    # -- skipping more beams than a scan has
    good = d / "good.mcap"
    add(
        "skip_beams_all",
        good,
        Expected(
            "exit 2: names the skip_beams keys and the beam count",
            2,
            ("input.skip_beams_start=100", "input.skip_beams_end=81", "all 181 beams"),
            args=("--set", "input.skip_beams_start=100", "--set", "input.skip_beams_end=81"),
        ),
    )


def _json_mcap(path: Path, scans: list[RawScan], scan_data: Callable[[RawScan], bytes] | None = None) -> Path:
    """A JSON MCAP of ``scans`` (scan i logged at ``scan_stamp(i)`` whatever its header stamp: a
    clock glitch in one message; CDR cannot hold a stamp of 1e18) and the valid odometry;
    ``scan_data`` replaces the scans' message bytes."""
    from mcap.writer import Writer

    from cornerslam_cli.logs.writers import LASERSCAN, ODOMETRY, JsonSerializer

    js = JsonSerializer()
    scan_data = scan_data or js.laserscan
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="", library="fault_corpus")
        ids = {
            name: w.register_channel(
                topic=name,
                message_encoding="json",
                schema_id=w.register_schema(name=typ, encoding="jsonschema", data=js.msgdef(typ).encode()),
            )
            for name, typ in (("/scan", LASERSCAN), ("/odom", ODOMETRY))
        }
        logged = [
            *zip(scans, map(scan_stamp, range(len(scans))), strict=True),
            *((o, o.stamp) for o in make_odoms()),
        ]
        for m, t in sorted(logged, key=lambda mt: mt[1]):
            ns = int(round(t * 1e9))
            if isinstance(m, OdomSample):
                w.add_message(ids["/odom"], ns, js.odometry(m, "odom", "base_link"), ns)
            else:
                w.add_message(ids["/scan"], ns, scan_data(m), ns)
        w.finish()
    return path


def _probe2_faults(d: Path, add: Callable[[str, Path, Expected], None]) -> None:
    """Faults found by the second probe of issue 13: quaternions with inf or overflowing components,
    far-future stamps, logs whose every message fails to decode, long topic names."""

    def unit(o):
        return (0.0, 0.0, math.sin(o.theta / 2), math.cos(o.theta / 2))

    def inf_in_one(o):
        return (0.0, 0.0, math.inf, 1.0) if round((o.stamp - T0) * RATE) == 5 else unit(o)

    add(
        "odom_quaternion_inf",
        write_mcap(d / "quat_inf.mcap", make_scans(), make_odoms(), odom_quaternion=inf_in_one),
        Expected(
            "processed; a sample with an inf quaternion component skipped, counted, warned",
            0,
            ("non-finite pose (quaternion (0.0, 0.0, inf, 1.0))",),
            dict(VALID_COUNTS, messages_failed=1),
        ),
    )
    add(
        "odom_quaternion_1e200",
        write_mcap(
            d / "quat_1e200.mcap",
            make_scans(),
            make_odoms(),
            odom_quaternion=lambda o: tuple(1e200 * v for v in unit(o)),
        ),
        Expected(
            "processed; quaternions whose squared length overflows normalised, warned",
            0,
            ("not of unit length: normalised",),
            VALID_COUNTS,
        ),
    )

    # -- one scan whose header stamp is 1e18 s: skipped alone, the later scans are not "backwards"
    for where, far in (("first", 0), ("mid", 10)):
        scans = [replace(s, stamp=1e18) if i == far else s for i, s in enumerate(make_scans())]
        add(
            f"stamp_far_future_{where}_scan_json_mcap",
            _json_mcap(d / f"far_stamp_{where}.mcap", scans),
            Expected(
                "processed; the one scan skipped, counted (no odometry near it), warned",
                0,
                ("1 in gaps of the odometry",),
                {"steps": N - 1, "scans_skipped": 1, "scan_time_backwards": 0},
            ),
        )
    far_scan = (replace(s, stamp=1e18) if i == 10 else s for i, s in enumerate(make_scans()))
    add(
        "stamp_far_future_scan_carmen",
        write_carmen(d / "far_stamp.clf", far_scan, make_odoms()),
        Expected(
            "processed; the one scan skipped, counted, warned",
            0,
            ("1 after the last odometry sample",),
            {"steps": N - 1, "scans_skipped": 1, "scan_time_backwards": 0},
        ),
    )

    # -- a CARMEN log whose only laser line is cut mid-line: the log is to blame, not a span
    flaser = f"FLASER 181 {' '.join(['2.5'] * 181)} 0 0 0 0 0 0 {T0 + 0.15:.3f} host {T0 + 0.15:.3f}"
    odom_lines = [f"ODOM {o.x} {o.y} {o.theta} 0 0 0 {o.stamp:.3f} host {o.stamp:.3f}" for o in make_odoms()]
    cut_laser = _write(d, "cut_flaser.clf", "\n".join([*odom_lines, flaser[: len(flaser) // 2]]))
    for name, args in (("", ()), ("_max_scans", ("--max-scans", "5")), ("_start", ("--start", "1"))):
        add(
            f"carmen_only_laser_line_cut{name}",
            cut_laser,
            Expected(
                "exit 2: the log has no complete laser line (not: the span selects no scan)",
                2,
                (
                    "CARMEN log 'cut_flaser.clf' has no complete laser line",
                    "its only FLASER line cannot be read (line 42:",
                    "give a log with whole laser lines",
                ),
                args=args,
            ),
        )

    # ... and whose only laser line holds a 20,000-character token: the reader's reason is cut short
    huge = flaser.replace(" 2.5 ", " " + "x" * 20000 + " ", 1)
    add(
        "carmen_only_laser_line_huge_token",
        _write(d, "huge_token.clf", "\n".join([*odom_lines, huge])),
        Expected(
            "exit 2: the log has no complete laser line, the bad token quoted short",
            2,
            (
                "its only FLASER line cannot be read (line 42:",
                "its reading 1 'xxxxxxxxxxxxxxxxx...xxxxxxxxxxxxxxxxxx' is not a number)",
            ),
        ),
    )

    # -- chunks not in time order and no summary (no chunk index): read in file order; the warning
    # says so instead of only blaming the stamps
    add(
        "mcap_chunks_unsorted_no_summary",
        write_mcap(
            d / "unsorted_no_summary.mcap", make_scans(), make_odoms(), shuffle_blocks=8, summary=False
        ),
        Expected(
            "processed; messages stored out of order skipped, counted, warned as such (no chunk index)",
            0,
            ("messages of '/scan' are stored after later ones", "no chunk index"),
            {"steps": (1, N - 1), "scan_time_backwards": (1, N - 1)},
        ),
    )

    # -- skip_beams_* leave beams in the first scan but none in later, shorter ones: warned
    def quarter(s: RawScan) -> RawScan:  # every 4th beam: 46 beams over the same 270°
        return replace(s, ranges=s.ranges[::4], angle_increment=4 * s.angle_increment)

    mixed = (s if i % 2 == 0 else quarter(s) for i, s in enumerate(make_scans()))
    add(
        "skip_beams_all_of_shorter_scans",
        write_mcap(d / "mixed_beams.mcap", mixed, make_odoms()),
        Expected(
            "processed; the later scans left without beams counted, warned",
            0,
            ("skip all beams of 20 shorter scans",),
            {"steps": N},
            args=("--set", "input.skip_beams_start=50"),
        ),
    )

    # -- nothing decodes: every scan, or every odometry sample; the error names the failures
    add(
        "scans_all_undecodable",
        _json_mcap(d / "scans_undecodable.mcap", list(make_scans()), lambda s: b"{not json"),
        Expected(
            "exit 2: names the decoding failures and the first one",
            2,
            (
                "scans_undecodable.mcap",
                f"{N} messages could not be decoded or held unusable values",
                "cannot decode a /scan message",
            ),
        ),
    )
    add(
        "odom_quaternions_all_zero",
        write_mcap(
            d / "quat_all_zero.mcap", make_scans(), make_odoms(), odom_quaternion=lambda o: (0.0,) * 4
        ),
        Expected(
            "exit 2: names the decoding failures and the first one",
            2,
            (
                "quat_all_zero.mcap",
                f"{N + 1} messages could not be decoded or held unusable values",
                "zero-length orientation quaternion",
            ),
        ),
    )


def _probe14_faults(d: Path, add: Callable[[str, Path, Expected], None]) -> None:
    """Faults found by the 14th probe: a ROS 2 bag directory whose metadata.yaml is not YAML (rosbags
    quotes PyYAML's error, several lines long: the error was printed on four lines); scan angles in
    degrees (processed without a word); an odometry sample 1e300 m away (an internal error)."""
    bag = d / "rosbag2"
    shutil.rmtree(bag, ignore_errors=True)
    write_rosbag2(bag, make_scans(), make_odoms())
    for name, metadata in (("not_yaml", b"rosbag2_bagfile_information: [\n"), ("nul", b"\x00\n")):
        damaged = d / f"rosbag2_metadata_{name}"
        shutil.rmtree(damaged, ignore_errors=True)
        shutil.copytree(bag, damaged)
        (damaged / "metadata.yaml").write_bytes(metadata)
        add(
            f"rosbag2_metadata_{name}",
            damaged,
            Expected(
                "exit 2: the bag and its metadata.yaml named, on one line",
                2,
                (f"cannot read ROS 2 bag 'rosbag2_metadata_{name}'", "metadata.yaml", "(check the bag)"),
            ),
        )

    # -- angles in degrees (a driver's or converter's mistake): 181 beams over 270 "radians", 43 turns
    degrees = (replace(s, angle_min=-135.0, angle_increment=1.5) for s in make_scans())
    add(
        "angles_in_degrees",
        write_mcap(d / "degrees.mcap", degrees, make_odoms()),
        Expected(
            "exit 2: every scan's beams span more than a full turn (it was processed into a map of noise)",
            2,
            ("degrees.mcap", f"all {N} scans on '/scan' were skipped", "beams over more than a full turn"),
        ),
    )
    # -- one odometry sample 1e300 m away (damaged bytes): it overflowed the motion noise (exit 1)
    far = make_odoms(edit=lambda i, p: p + np.array([1e300, 0.0, 0.0]) if i == 10 else p)
    add(
        "odom_one_sample_1e300",
        write_mcap(d / "odom_1e300.mcap", make_scans(), far),
        Expected(
            "processed; the far sample skipped, counted, warned",
            0,
            ("has a position (1e+300,", "farther than 1e+09 m: skipped"),
            dict(VALID_COUNTS, messages_failed=1),
        ),
    )
    full_turn = (replace(s, angle_min=-math.pi, angle_increment=2 * math.pi / 180) for s in make_scans())
    add(
        "full_turn_with_the_first_beam_repeated",
        write_mcap(d / "full_turn.mcap", full_turn, make_odoms()),
        Expected(
            "processed: a 360° scan may repeat its first beam's direction",
            0,
            counts={"steps": N, "scans_bad_geometry": 0},
        ),
    )


# --------------------------------------------------------------------------- the long log
def build_long_log(d: str | Path, n: int = 100_000, beams: int = 64) -> Path:
    """An n-scan log of tiny scans (streamed: memory does not grow with n); reused if present in ``d``."""
    path = Path(d) / f"long_{n}_{beams}.mcap"
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.exists():
        tmp = path.with_name(path.name + ".tmp")
        write_mcap(tmp, make_scans(n, beams=beams), make_odoms(n + 1))
        tmp.rename(path)
    return path


def main(argv: list[str]) -> None:
    d = Path(argv[1] if len(argv) > 1 else "fault_corpus")
    for name, (path, exp) in build_corpus(d).items():
        print(f"{name:<36} {path.name:<24} exit {exp.exit_code}  {exp.behaviour}")


if __name__ == "__main__":
    main(sys.argv)
