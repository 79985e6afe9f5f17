"""benchmarks/report_screenshots.py: the checks a person would make on report.html (verdict), and the
headless-Chromium measurement behind them on small pages made here (skipped where no chromium)."""

from __future__ import annotations

import importlib.util
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "report_screenshots.py"
SPEC = importlib.util.spec_from_file_location("report_screenshots", SCRIPT)
shots = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(shots)

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
PNG_1PX = (  # a 1×1 PNG
    "iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mP8z8DwHwAFBQIAX8jx0gAAAABJRU5ErkJggg=="
)
ATE_TABLE = "<table><tr><th>trajectory</th><th>ATE RMSE [m]</th></tr><tr><td>0.04</td></tr></table>"


def good_facts() -> dict:
    return {
        "scroll_width": 1400,
        "page_height": 3000,
        "images": [{"alt": "map", "complete": True, "width": 800}],
        "cells": ["trajectory", "ATE RMSE [m]", "corrected", "0.04", "—"],
        "headers": ["trajectory", "ATE RMSE [m]"],
    }


def test_verdict_passes_a_good_page():
    assert shots.verdict(good_facts()) == []


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"scroll_width": 1401}, "1401 px wide"),
        ({"images": []}, "no figures"),
        ({"images": [{"alt": "map", "complete": True, "width": 0}]}, "'map' did not load"),
        ({"cells": ["corrected", "nan"]}, "'nan'"),
        ({"cells": ["None"]}, "'None'"),
        ({"headers": ["trajectory (map)", "occupied cells"]}, "no accuracy"),
    ],
)
def test_verdict_names_each_defect(change, message):
    facts = good_facts() | change
    failures = shots.verdict(facts)
    assert len(failures) == 1 and message in failures[0]


def page(tmp_path: Path, name: str, body: str) -> Path:
    path = tmp_path / f"{name}.html"
    path.write_text(f"<!DOCTYPE html><html><head><meta charset='utf-8'></head><body>{body}</body></html>")
    return path


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium on PATH (apt-get install chromium)")
def test_browser_measures_what_a_person_sees(tmp_path):
    good = page(tmp_path, "good", f'<img alt="map" src="data:image/png;base64,{PNG_1PX}">{ATE_TABLE}')
    wide = '<div style="width:2000px">wide</div>'
    nan_table = "<table><tr><td>nan</td></tr></table>"
    bad = page(tmp_path, "bad", f'{wide}<img alt="gone" src="missing.png">{nan_table}')
    browser = shots.Browser(CHROMIUM)
    try:
        good_facts = shots.shoot(browser, good, tmp_path / "good.png")
        bad_facts = shots.shoot(browser, bad, tmp_path / "bad.png")
    finally:
        browser.close()
    assert shots.verdict(good_facts) == []
    assert (tmp_path / "good.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    failures = " | ".join(shots.verdict(bad_facts))
    for message in ("2008 px wide", "'gone' did not load", "'nan'", "no accuracy"):
        assert message in failures
