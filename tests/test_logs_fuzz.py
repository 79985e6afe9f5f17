"""Fuzz: random bytes and mutated valid logs never make a reader raise anything but LogError."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest
from _log_fixtures import make_odoms, make_scans, write_log
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cornerslam_cli.errors import LogError
from cornerslam_cli.logs import open_log

FUZZ = settings(max_examples=100, deadline=None, suppress_health_check=list(HealthCheck))
_TMP = Path(tempfile.mkdtemp(prefix="cornerslam-fuzz-"))
VALID = {}
for fmt, suffix in [("mcap-cdr", ".mcap"), ("mcap-ros1", ".mcap"), ("rosbag1", ".bag"), ("carmen", ".log")]:
    d = _TMP / fmt
    d.mkdir()
    VALID[fmt] = (
        write_log(
            fmt,
            d,
            make_scans(6, beams=91),
            make_odoms(6),
            **({} if fmt == "carmen" else {"tf_static": (0.1, 0, 0)}),
        ).read_bytes(),
        suffix,
    )


def read_everything(path: Path) -> None:
    try:
        log = open_log(path)
    except LogError:
        return
    try:
        log.info()
        for _ in log.messages():
            pass
        log.laser_to_base()
    except LogError:
        pass
    finally:
        log.close()


@FUZZ
@given(
    data=st.binary(min_size=0, max_size=400),
    suffix=st.sampled_from([".mcap", ".bag", ".log", ".clf", ".gz", ""]),
)
def test_random_bytes(data, suffix):
    p = _TMP / f"random{suffix}"
    p.write_bytes(data)
    read_everything(p)


@pytest.mark.parametrize("fmt", sorted(VALID))
@FUZZ
@given(data=st.data())
def test_mutated_valid_log(fmt, data):
    raw, suffix = VALID[fmt]
    buf = bytearray(raw)
    kind = data.draw(st.sampled_from(["flip", "truncate", "splice"]))
    if kind == "truncate":
        buf = buf[: data.draw(st.integers(0, len(buf)))]
    else:
        for _ in range(data.draw(st.integers(1, 8))):
            i = data.draw(st.integers(0, len(buf) - 1))
            if kind == "flip":
                buf[i] = data.draw(st.integers(0, 255))
            else:
                buf[i : i + 8] = data.draw(st.binary(min_size=0, max_size=16))
    p = _TMP / f"mutated-{fmt}{suffix}"
    p.write_bytes(bytes(buf))
    read_everything(p)
