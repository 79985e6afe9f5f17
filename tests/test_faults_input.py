"""Reading faults that need more than a file of the fault corpus, through the CLI: logs that are pipes
(``<(zcat x.mcap)``), FIFOs or devices; log names that are not UTF-8; and memory that must not grow
with scans that find no odometry."""

from __future__ import annotations

import json
import os
import threading
from contextlib import contextmanager
from pathlib import Path

import pytest
from click.testing import CliRunner
from fault_corpus import N, check_error_line, make_odoms, make_scans, peak_bytes, write_gt

from cornerslam_cli.cli import cli
from cornerslam_cli.logs.writers import write_mcap, write_rosbag2

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="POSIX only")


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def good(tmp_path_factory) -> Path:
    return write_mcap(tmp_path_factory.mktemp("in") / "good.mcap", make_scans(), make_odoms())


# ---------------------------------------------------------------------------- pipes, FIFOs, devices
@contextmanager
def fifo_writer(path: Path):
    """A thread that opens ``path`` for writing and closes it at once: if cornerslam opened the FIFO it
    would read an empty file instead of hanging the test. At the end the thread is released."""
    t = threading.Thread(target=lambda: open(path, "wb").close(), daemon=True)
    t.start()
    try:
        yield
    finally:
        if t.is_alive():  # nobody opened the read end, as it should be: open it to let the thread go
            fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
            t.join(5)
            os.close(fd)
        assert not t.is_alive()


COMMANDS = {
    "run": ("run", "{log}", "--out", "{tmp}/out"),
    "info": ("info", "{log}"),
    "compare": ("compare", "{log}", "--assoc", "icnn", "--out", "{tmp}/cmp"),
    "extract": ("extract", "{log}"),
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_fifo_named_like_a_log_is_refused_without_hanging(command, tmp_path):
    fifo = tmp_path / "x.mcap"
    os.mkfifo(fifo)
    with fifo_writer(fifo):
        res = invoke(*(a.format(log=fifo, tmp=tmp_path) for a in COMMANDS[command]))
    check_error_line(res, ("x.mcap", "is a pipe, not a file", "save it to a file first"))
    assert not (tmp_path / "out").exists() and not (tmp_path / "cmp").exists()


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_dash_for_standard_input_says_so(command, tmp_path, monkeypatch):
    """`cat x.mcap | cornerslam run -`: "log '-' does not exist (check the path)", as if a file named
    '-' had been meant; standard input is read as a pipe would be: not at all."""
    monkeypatch.chdir(tmp_path)
    res = invoke(*(a.format(log="-", tmp=tmp_path) for a in COMMANDS[command]))
    check_error_line(res, ("log '-' (standard input) cannot be read", "save it to a file first"))
    assert not (tmp_path / "out").exists() and not (tmp_path / "cmp").exists()


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_process_substitution_is_refused_not_read_as_empty(command, tmp_path, good):
    """``cornerslam run <(cat good.mcap)``: the log is read several times (laser preset, index, laser
    mount, messages), a pipe only once; it used to say 'is empty'."""
    r, w = os.pipe()
    try:
        os.write(w, good.read_bytes()[:4096])
        res = invoke(*(a.format(log=f"/dev/fd/{r}", tmp=tmp_path) for a in COMMANDS[command]))
    finally:
        os.close(r)
        os.close(w)
    check_error_line(res, (f"/dev/fd/{r}", "is a pipe, not a file"))


def test_a_device_is_refused(tmp_path):
    check_error_line(
        invoke("run", os.devnull, "--out", tmp_path / "o"), ("is a character device, not a file",)
    )


def test_batch_fails_the_rows_of_a_pipe_and_runs_the_others(tmp_path, good):
    """Also with the laser preset off (the log is then first touched by the resume hash)."""
    fifo = tmp_path / "f.mcap"
    os.mkfifo(fifo)
    with fifo_writer(fifo):
        res = invoke(
            "batch", fifo, good, "--out", tmp_path / "b", "--jobs", "1", "--set", "input.laser_preset=none"
        )
    assert res.exit_code == 2, res.output  # one combination failed on bad input
    assert res.stderr.splitlines()[-1].startswith("error: 1 of 2 combinations failed: see ")
    rows = (tmp_path / "b" / "batch.csv").read_text().splitlines()[1:]
    assert rows[0].startswith(f"{fifo},pca,failed,") and "is a pipe" in rows[0]
    assert rows[1].startswith(f"{good},pca,ok,")


# ---------------------------------------------------------------------------- a ROS 2 bag run from inside
def test_run_dot_inside_a_ros2_bag_directory(tmp_path, monkeypatch):
    """`cd BAG && cornerslam run .` (and `run ..` from a folder inside it): the bag runs, its output is
    named after the bag's directory and its ground truth found beside it (an internal error: '.' has
    no file name)."""
    bag = write_rosbag2(tmp_path / "bag", make_scans(), make_odoms(), storage="mcap")
    write_gt(bag)  # tmp_path/bag.gt.tum
    monkeypatch.chdir(bag)
    res = invoke("run", ".", "-q")
    assert res.exit_code == 0, res.output
    s = json.loads((bag / "cornerslam_out" / "bag_pca" / "summary.json").read_text())
    assert s["counts"]["steps"] == N and s["accuracy"]["ground_truth"].endswith("/bag.gt.tum")
    (bag / "sub").mkdir()
    monkeypatch.chdir(bag / "sub")
    res = invoke("run", "..", "--out", tmp_path / "o", "-q")
    assert res.exit_code == 0, res.output
    assert json.loads((tmp_path / "o" / "summary.json").read_text())["accuracy"]["ate"]["rmse"] < 0.01


# ---------------------------------------------------------------------------- names that are not UTF-8
@pytest.fixture(scope="module")
def latin1_log(tmp_path_factory) -> Path:
    """A log named b'log\\xe9.mcap' (latin-1 'é'), ground truth beside it (also not UTF-8)."""
    d = tmp_path_factory.mktemp("latin1")
    path = Path(os.fsdecode(os.path.join(os.fsencode(d), b"log\xe9.mcap")))
    return write_gt(write_mcap(path, make_scans(), make_odoms()))


def strict_json(path: Path) -> dict:
    """The file as strict UTF-8 JSON without escaped lone surrogates."""
    text = path.read_bytes().decode("utf-8")
    assert "\\udc" not in text.lower(), text
    return json.loads(text)


def test_run_and_compare_a_log_whose_name_is_not_utf8(latin1_log, tmp_path):
    res = invoke("run", latin1_log, "--out", tmp_path / "o")
    assert res.exit_code == 0, res.output
    s = strict_json(tmp_path / "o" / "summary.json")
    assert s["input"]["log"].endswith("log\ufffd.mcap") and s["counts"]["steps"] == N
    assert s["accuracy"]["ground_truth"].endswith("log\ufffd.gt.tum")
    res = invoke("compare", latin1_log, "--assoc", "icnn,pca", "--out", tmp_path / "c", "-q")
    assert res.exit_code == 0, res.output
    assert strict_json(tmp_path / "c" / "pca" / "summary.json")["counts"]["steps"] == N


def test_mcap_out_into_a_directory_whose_name_is_not_utf8(latin1_log, tmp_path):
    """The results MCAP's metadata names the output directory: UTF-8 with U+FFFD (it crashed)."""
    from mcap.reader import make_reader

    out = Path(os.fsdecode(os.path.join(os.fsencode(tmp_path), b"o\xe9")))
    res = invoke("run", latin1_log, "--out", out, "--mcap-out", out / "r.mcap", "-q")
    assert res.exit_code == 0, res.output
    with open(out / "r.mcap", "rb") as f:
        meta = next(m for m in make_reader(f).iter_metadata() if m.name == "cornerslam")
    assert meta.metadata["results"].endswith("o\ufffd") and meta.metadata["log"].endswith("log\ufffd.mcap")


def test_figures_and_results_mcap_draw_a_ground_truth_whose_name_is_not_utf8(latin1_log, tmp_path):
    """summary.json shows the ground truth's name with U+FFFD; the figures and the results MCAP
    still draw it, from the file the run read (they re-read the printable name and dropped it)."""
    from mcap.reader import make_reader

    out = tmp_path / "o"
    res = invoke("run", latin1_log, "--out", out, "--plot", "--mcap-out", tmp_path / "r.mcap")
    assert res.exit_code == 0, res.output
    assert "not drawn" not in res.stderr, res.stderr
    with open(tmp_path / "r.mcap", "rb") as f:
        topics = {c.topic for c in make_reader(f).get_summary().channels.values()}
    assert "/cornerslam/ground_truth_path" in topics, topics
    res = invoke("compare", latin1_log, "--assoc", "icnn", "--out", tmp_path / "c")
    assert res.exit_code == 0 and "not drawn" not in res.stderr, res.output


def test_info_batch_and_errors_with_a_name_that_is_not_utf8(latin1_log, tmp_path, monkeypatch):
    res = invoke("info", latin1_log)
    assert res.exit_code == 0 and "log\ufffd.mcap" in res.output and "/scan" in res.output, res.output
    monkeypatch.chdir(tmp_path)  # the default output directory is named after the log
    res = invoke("run", latin1_log)
    assert res.exit_code == 0 and "cornerslam_out/log\ufffd_pca\n" in res.output, res.output
    check_error_line(invoke("run", latin1_log, "--scan-topic", "/nope"), ("log\ufffd.mcap", "/nope"))
    res = invoke("batch", latin1_log, "--out", tmp_path / "b", "--jobs", "1", "-q")
    assert res.exit_code == 0, res.output
    row = (tmp_path / "b" / "batch.csv").read_bytes().decode("utf-8").splitlines()[1]
    assert "log\ufffd.mcap,pca,ok," in row


# ---------------------------------------------------------------------------- memory


def test_scans_without_odometry_do_not_grow_memory(tmp_path):
    """A log whose odometry ends after 1 s (e.g. odometry on the wrong topic): 1,500 and 4,500 later
    scans read, synchronised and skipped with the same peak memory (every one was held to the end:
    612 MB vs 129 MB on 20,000 real scans); each is counted. Small chunks, so that both logs have
    many (the reader holds one decompressed chunk)."""
    from cornerslam_cli.config import load_config
    from cornerslam_cli.frontend import frames, open_input

    cfg = load_config()

    def run(n):
        log = write_mcap(tmp_path / f"l{n}.mcap", make_scans(n, beams=64), make_odoms(11), chunk_size=1 << 16)
        src = open_input(log, cfg)
        peak = peak_bytes(lambda: sum(1 for _ in frames(src, cfg)))
        assert src.stats.scans_in == n and src.stats.after_last_odom == n - 10
        return peak

    small, large = run(1500), run(4500)
    assert large < 1.3 * small, (small, large)


# ---------------------------------------------------------------------------- long names in errors
LONG = "/" + "x" * 100_000


@pytest.fixture(scope="module")
def tf_log(tmp_path_factory) -> Path:
    return write_mcap(tmp_path_factory.mktemp("tf") / "tf.mcap", make_scans(), make_odoms(), odom_as_tf=True)


@pytest.mark.parametrize(
    "args",
    [
        ("--scan-topic", LONG),
        ("--odom-topic", LONG),
        ("--set", f"input.odom_frame={LONG[1:]}"),
        ("--set", f"input.base_frame={LONG[1:]}"),
    ],
    ids=["scan_topic", "odom_topic", "odom_frame", "base_frame"],
)
@pytest.mark.parametrize("command", ["run", "info"])
def test_a_100000_character_topic_or_frame_is_quoted_shortened(command, args, tf_log, tmp_path):
    """The error line names the topic/frame by its start and end, not all 100,000 characters."""
    if command == "info" and args[0] == "--set":
        pytest.skip("info has no --set")
    out = ("--out", tmp_path / "out") if command == "run" else ()
    res = invoke(command, tf_log, *out, *args)
    check_error_line(res, ("tf.mcap", "xxxxxxxxxx...xxxxxxxxxx"))
    assert len(res.stderr.strip().splitlines()[-1]) < 400


def test_tf_odometry_to_base_footprint_names_the_frames_and_the_key_to_set(tmp_path):
    """nav2's odom→base_footprint on /tf, base_link the default: run's error names the transforms the
    topic has and the --set that fixes it, which then runs, and info ends with that error (before: run
    said only "set the frames (odom_frame/base_frame)" after reading the whole log, and info exited 0
    saying run would use /tf; found by a hostile-user probe)."""
    log = write_mcap(
        tmp_path / "fp.mcap", make_scans(), make_odoms(), odom_as_tf=True, base_frame="base_footprint"
    )
    res = invoke("run", log, "--out", tmp_path / "out", "-q")
    check_error_line(res, ("fp.mcap", "odom→base_footprint", "--set input.base_frame=base_footprint"))
    assert not (tmp_path / "out").exists()
    res = invoke("run", log, "--out", tmp_path / "out", "-q", "--set", "input.base_frame=base_footprint")
    assert res.exit_code == 0, res.output
    res = invoke(
        "info", log
    )  # info read every tf message: it says so, as run would (it said run would use /tf)
    check_error_line(res, ("fp.mcap", "odom→base_footprint", "--set input.base_frame=base_footprint"))
    assert "odometry  /tf (tf odom→base_link)" in res.stdout


def test_a_100000_character_topic_in_the_log_is_listed_shortened(tmp_path):
    """The log's LaserScan topic is named with 100,000 characters: the error listing it shortens it."""
    log = write_mcap(tmp_path / "long.mcap", make_scans(), make_odoms(), scan_topic=LONG)
    res = invoke("run", log, "--out", tmp_path / "out", "--scan-topic", "/scan")
    check_error_line(
        res, ("long.mcap", "'/scan'", "LaserScan topics: /xxxxxxxxxx", "xxxxxxxxxx...xxxxxxxxxx")
    )
    assert len(res.stderr.strip().splitlines()[-1]) < 400


# ---------------------------------------------------------------------------- endless text inputs
@contextmanager
def endless_fifo(path: Path, line: bytes):
    """A FIFO at ``path`` fed ``line`` forever by a thread (``yes LINE > path``) until the reader
    closes it."""
    os.mkfifo(path)

    def feed():
        try:
            with open(path, "wb") as f:
                while True:
                    f.write(line * 4096)
        except (BrokenPipeError, OSError):
            pass

    t = threading.Thread(target=feed, daemon=True)
    t.start()
    try:
        yield path
    finally:
        t.join(10)
        assert not t.is_alive()


@pytest.mark.parametrize(
    "option, what", [("--ground-truth", "ground truth"), ("--relations", "relations file")]
)
def test_an_endless_ground_truth_or_relations_pipe_is_refused_at_the_limit(
    option, what, good, tmp_path, monkeypatch
):
    """`--ground-truth <(yes "1 2 3 4 0 0 0 1")` read whole ran out of memory (exit 1): refused once
    it passes MAX_ROWS_BYTES (1 MiB here)."""
    import cornerslam_cli.textfile as textfile

    monkeypatch.setattr(textfile, "MAX_ROWS_BYTES", 1 << 20)
    with endless_fifo(tmp_path / "endless", b"1 2 3 4 0 0 0 1\n") as p:
        res = invoke("run", good, "--out", tmp_path / "out", option, p)
    check_error_line(res, (f"{what} '{p}'", "is larger than 1024 KiB"))
    assert not (tmp_path / "out").exists()
