"""report.html (report/html.py): one self-contained file, parsed back with html.parser."""

from __future__ import annotations

import base64
import json
import re
import shutil
from html.parser import HTMLParser
from pathlib import Path

import matplotlib
import pytest
from test_report_plots import ASSOCS, PNG_SIGNATURE, make_report_outputs

from cornerslam_cli.report.html import write_report
from cornerslam_cli.report.plots import COMPARE_FIGURES, RUN_FIGURES
from cornerslam_cli.report.tables import COMPARISON_COLUMNS, read_csv


class Page(HTMLParser):
    """Collects images, tables (rows of (text, class) cells), ids, links and any external reference."""

    def __init__(self, text: str):
        super().__init__()
        self.images: list[dict] = []
        self.tables: list[list[list[tuple[str, str]]]] = []
        self.ids: set[str] = set()
        self.hrefs: list[str] = []
        self.scripts = 0
        self._cell: list | None = None
        self.feed(text)
        self.close()

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if "id" in a:
            self.ids.add(a["id"])
        if tag == "img":
            self.images.append(a)
        elif tag == "script":
            self.scripts += 1
        elif tag in ("a", "link") and "href" in a:
            self.hrefs.append(a["href"])
        elif tag == "table":
            self.tables.append([])
        elif tag == "tr":
            self.tables[-1].append([])
        elif tag in ("td", "th"):
            self._cell = ["", a.get("class") or ""]

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self.tables[-1][-1].append((self._cell[0].strip(), self._cell[1]))
            self._cell = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell[0] += data


@pytest.fixture(scope="module")
def reports(tmp_path_factory, sim_log):
    """write_report on fresh copies (no PNGs yet: the report must draw them itself)."""
    run_dir, cmp_dir = make_report_outputs(tmp_path_factory, sim_log)
    mine = tmp_path_factory.mktemp("html")
    for src, name in ((run_dir, "run"), (cmp_dir, "cmp")):
        shutil.copytree(src, mine / name, ignore=shutil.ignore_patterns("*.png", "report.html"))
    return write_report(mine / "run"), write_report(mine / "cmp")


def check_self_contained(text: str, page: Page) -> None:
    assert page.scripts == 0
    for img in page.images:
        assert img["src"].startswith("data:image/png;base64,"), img["src"][:40]
        assert base64.b64decode(img["src"].split(",", 1)[1])[:8] == PNG_SIGNATURE
        assert img.get("alt")
    assert all(h.startswith("#") for h in page.hrefs), page.hrefs
    lowered = text.lower()
    for bad in ('src="http', "src='http", 'href="http', "url(", "<link", "@import"):
        assert bad not in lowered, bad


def table_with_header(page: Page, first: str) -> list[list[tuple[str, str]]]:
    found = [t for t in page.tables if t and t[0] and t[0][0][0] == first]
    assert found, f"no table whose first header is {first!r}"
    return found[0]


def test_run_report_is_self_contained_with_every_figure(reports):
    path = reports[0]
    assert path.name == "report.html"
    text = path.read_text(encoding="utf-8")
    page = Page(text)
    check_self_contained(text, page)
    assert [img["alt"].split(": ")[-1] for img in page.images] == list(RUN_FIGURES)
    for name in RUN_FIGURES:  # drawn because they were missing
        assert (path.parent / name).is_file()


def test_run_report_summary_matches_summary_json(reports):
    path = reports[0]
    summary = json.loads((path.parent / "summary.json").read_text())
    page = Page(path.read_text(encoding="utf-8"))
    facts = {row[0][0]: row[1][0] for t in page.tables for row in t if len(row) == 2 and row[0][1] == "name"}
    assert facts["steps"] == str(summary["counts"]["steps"])
    assert facts["landmarks"] == str(summary["counts"]["landmarks"])
    assert facts["matched corners"] == str(summary["counts"]["matched_total"])
    assert facts["associator"] == summary["assoc"]
    assert facts["log"] == summary["input"]["log"]
    acc = table_with_header(page, "trajectory")
    # the scan-matched odometry and the online estimate, as `run` prints them (they were left out)
    names = [r[0][0] for r in acc[1:]]
    assert names[:2] == ["smoothed (pose graph)", "odometry"]  # as Fig 16's legend names it (submaps)
    keys = {"scan-matched odometry": "scan_odom_ate", "online (causal)": "online_ate"}
    assert names[2:] == [k for k, v in keys.items() if summary["accuracy"].get(v)]
    assert float(acc[1][1][0]) == pytest.approx(summary["accuracy"]["ate"]["rmse"], rel=1e-3)
    for row in acc[3:]:
        assert float(row[1][0]) == pytest.approx(summary["accuracy"][keys[row[0][0]]]["rmse"], rel=1e-3)
    text = path.read_text(encoding="utf-8")
    assert "<details><summary>Resolved configuration" in text
    assert "association" in text and "&quot;method&quot;: &quot;pca&quot;" in text


def test_compare_report_has_table_figures_and_a_section_per_associator(reports):
    path = reports[1]
    text = path.read_text(encoding="utf-8")
    page = Page(text)
    check_self_contained(text, page)
    # comparison.csv's columns; the loop-closing ones (issue 16: the runs have submaps) in their own table
    main, loops = [t for t in page.tables if t and t[0] and t[0][0][0] == "assoc"]
    # (refine_factors is left out when empty: graph.refine off)
    assert [c[0] for c in main[0]] + [c[0] for c in loops[0][1:]] == [
        c for c in COMPARISON_COLUMNS if c != "refine_factors"
    ]
    for rows in (main, loops):
        assert [r[0][0] for r in rows[1:]] == ASSOCS
        assert all(len(r) == len(rows[0]) for r in rows[1:])
    alts = [img["alt"] for img in page.images]
    assert alts[: len(COMPARE_FIGURES)] == list(COMPARE_FIGURES)
    assert alts[len(COMPARE_FIGURES) :] == [f"{a}: {n}" for a in ASSOCS for n in RUN_FIGURES]
    assert {f"assoc-{a}" for a in ASSOCS} <= page.ids
    assert {f"#assoc-{a}" for a in ASSOCS} <= set(page.hrefs)


def test_compare_report_highlights_the_best_values(reports):
    path = reports[1]
    table = read_csv(path.parent / "comparison.csv")
    rows = table_with_header(Page(path.read_text(encoding="utf-8")), "assoc")[1:]
    for col, pick in (("t_match_total", min), ("ate_rmse", min)):
        vals = list(table[col])
        j = COMPARISON_COLUMNS.index(col)
        marked = [i for i, r in enumerate(rows) if "best" in r[j][1]]
        if len(set(vals)) < 2:
            assert marked == []
        else:
            assert marked == [i for i, v in enumerate(vals) if v == pick(vals)], col
    # columns without a better direction are never marked
    for col in ("assoc", "steps", "landmarks", "odom_ate_rmse", "matched_total"):  # (more is not better)
        j = COMPARISON_COLUMNS.index(col)
        assert not any("best" in r[j][1] for r in rows)


def test_report_escapes_text(tmp_path, reports):
    run = tmp_path / "run"
    shutil.copytree(reports[0].parent, run)
    summary = json.loads((run / "summary.json").read_text())
    summary["warnings"] = ['<script>alert("x")</script> & <b>bold</b>']
    summary["input"]["log"] = "/logs/<evil>.mcap"
    (run / "summary.json").write_text(json.dumps(summary))
    text = write_report(run).read_text(encoding="utf-8")
    assert "<script>" not in text and "<b>bold" not in text and "<evil>" not in text
    assert "&lt;script&gt;alert(&quot;x&quot;)&lt;/script&gt; &amp; &lt;b&gt;bold&lt;/b&gt;" in text
    page = Page(text)
    assert page.scripts == 0
    facts = {r[0][0]: r[1][0] for t in page.tables for r in t if len(r) == 2}
    assert facts["log"] == "/logs/<evil>.mcap"  # the parser unescapes: the text survives intact


def test_write_report_returns_path_inside_dir(reports):
    for p in reports:
        assert isinstance(p, Path) and p.parent.is_dir() and p.stat().st_size > 50_000


FONT = Path(matplotlib.get_data_path()) / "fonts" / "ttf"  # DejaVu Sans: what system-ui falls back to


def min_table_width(rows: list[list[str]], font_px: float, pad_px: float) -> float:
    """The narrowest a browser can lay out a table (px): per column its widest unbreakable piece (a
    header breaks at spaces and after underscores, a cell at spaces), plus padding and borders;
    header text is bold. Measured with DejaVu Sans, what system-ui falls back to on Linux."""
    from PIL import ImageFont

    bold = ImageFont.truetype(str(FONT / "DejaVuSans-Bold.ttf"), size=round(font_px))
    regular = ImageFont.truetype(str(FONT / "DejaVuSans.ttf"), size=round(font_px))
    widths = [0.0] * len(rows[0])
    for i, row in enumerate(rows):
        font = bold if i == 0 else regular
        for j, text in enumerate(row):
            pieces = re.split(r"(?<=_)|\s+", text) if i == 0 else text.split()
            widths[j] = max([widths[j]] + [font.getlength(p) for p in pieces])
    return sum(widths) + len(widths) * (2 * pad_px + 1) + 1


def test_compare_table_fits_a_1400_px_page_with_the_widest_numbers(reports):
    text = reports[1].read_text(encoding="utf-8")
    assert '<table class="wide">' in text and "rel_<wbr>trans_<wbr>mean" in text
    rows = [[c[0] for c in r] for r in table_with_header(Page(text), "assoc")]
    body = 1200  # CSS max-width of the page body: a 1,400 px window shows it whole
    font, pad = 16 * 0.75, 16 * 0.75 * 0.25  # table.wide: .75em, padding .25em
    assert min_table_width(rows, font, pad) <= body
    # every cell as wide as a time or an error of 4 significant digits in the millisecond range gets
    widest = [rows[0]] + [[r[0]] + ["0.001234"] * (len(r) - 1) for r in rows[1:]]
    assert min_table_width(widest, font, pad) <= body
    assert min_table_width(widest, 16 * 0.92, 16 * 0.92 * 0.6) > body  # the table as it was did not fit


def test_run_report_shows_the_relation_metric_without_ground_truth(tmp_path, reports):
    """A run scored by --relations only (no ground truth, no ATE): the report shows the relation
    metric stdout prints, and no accuracy table of dashes."""
    run = tmp_path / "run"
    shutil.copytree(reports[0].parent, run)
    summary = json.loads((run / "summary.json").read_text())
    rel = {
        "n": 120,
        "n_total": 130,
        "trans_mean": 0.167,
        "trans_std": 0.158,
        "rot_mean_deg": 2.5,
        "rot_std_deg": 3.0,
    }
    odom = {
        "n": 120,
        "n_total": 130,
        "trans_mean": 5.9,
        "trans_std": 9.0,
        "rot_mean_deg": 20.0,
        "rot_std_deg": 1,
    }
    summary["accuracy"] = {"relations_file": "intel.relations", "relations": rel, "odom_relations": odom}
    del summary["counts"]["submaps"]  # the single map's (the paper's): the EKF's own estimate
    (run / "summary.json").write_text(json.dumps(summary))
    page = Page(write_report(run).read_text(encoding="utf-8"))
    assert not [t for t in page.tables if t and t[0] and t[0][0][0] == "trajectory"]  # no ATE
    rows = table_with_header(page, "trajectory (relations)")
    assert [[c[0] for c in r] for r in rows[1:]] == [
        ["corrected (EKF)", "0.167", "0.158", "2.5", "3", "120 of 130"],
        ["odometry", "5.9", "9", "20", "1", "120 of 130"],
    ]


def test_run_report_names_the_times_and_shows_the_map_consistency(reports):
    page = Page(reports[0].read_text(encoding="utf-8"))
    summary = json.loads((reports[0].parent / "summary.json").read_text())
    facts = {r[0][0]: r[1][0] for t in page.tables for r in t if len(r) == 2}
    assert facts["wall-clock time [s]"] == f"{summary['timing']['wall_time']:.4g}"
    assert "matching time [s]" in facts and not any(
        " time time" in k or "_" in k for k in facts if "[s]" in k
    )
    c = summary["consistency"]
    rows = [[cell[0] for cell in r] for r in table_with_header(page, "trajectory (map)")[1:]]
    assert rows[0][:3] == ["smoothed (pose graph)", str(c["occupied_cells"]), f"{c['cells_vs_odom']:.4g}"]
    assert rows[1][:3] == ["odometry", str(c["odom_occupied_cells"]), "1"]
    assert float(rows[0][3]) == pytest.approx(100 * c["revisit_mean"], rel=1e-3)
