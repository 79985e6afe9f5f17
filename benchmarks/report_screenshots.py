"""Screenshots of ``report.html`` as a person sees it, and the checks a person would make on it.

    python benchmarks/report_screenshots.py [--data DIR] [--work DIR] [--out docs/results/report_shots]
        [--chromium PATH] [--reuse]

Needs a headless Chromium (Debian: ``apt-get install chromium``); driven over the DevTools protocol on
a pipe (``--remote-debugging-pipe``), so nothing beyond the standard library is needed on our side.

Two runs, each ``cornerslam run LOG --plot``: the simulated sample (``sample_logs/sim_office.mcap``,
501 steps, ATE against its ground truth) and a long real log (radish ``infinite-corridor.log``, 1,941
scans, ATE against the corrected poses beside it; ``--data`` as in real_logs.py). Each report.html is
opened at 1,400 px width and captured full-page into ``OUT/<name>.png``; then, in the page:

* the page is no wider than 1,400 px (``document.documentElement.scrollWidth``: no sideways scroll);
* every ``<img>`` loaded (``naturalWidth > 0``);
* no table cell reads ``nan``, ``None``, ``null`` or ``inf``;
* the accuracy table (ATE) or the relations table is there.

The measured facts and any failures go to ``OUT/checks.json``; the exit code is 1 when a check fails.
The screenshots are for looking at: what they show is written up in docs/results/report_shots.md.
"""

from __future__ import annotations

import argparse
import base64
import fcntl
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from real_logs import CLI, ROOT, default_data  # noqa: E402

WIDTH = 1400
BAD_CELLS = ("nan", "none", "null", "inf", "-inf")
ACCURACY_HEADERS = ("ATE RMSE [m]", "trajectory (relations)")

# what a person would look at, measured in the page (returned as one JSON object)
MEASURE = """(() => {
  const cells = [...document.querySelectorAll('td, th')].map(c => c.textContent.trim());
  const heads = [...document.querySelectorAll('th')].map(c => c.textContent.trim());
  return {
    scroll_width: document.documentElement.scrollWidth,
    page_height: document.documentElement.scrollHeight,
    images: [...document.images].map(i => ({alt: i.alt, complete: i.complete, width: i.naturalWidth})),
    cells: cells,
    headers: heads,
  };
})()"""


def run_report(name: str, log: Path, work: Path, reuse: bool) -> Path:
    """``cornerslam run LOG --plot`` into ``work/name``; its report.html."""
    out = work / name
    report = out / "report.html"
    if reuse and report.is_file():
        return report
    cmd = [*CLI, "run", str(log), "--plot", "--out", str(out), "-q"]
    print("+", " ".join(cmd), flush=True)
    subprocess.run(cmd, check=True, cwd=ROOT)
    return report


def verdict(facts: dict, width: int = WIDTH) -> list[str]:
    """The checks a person would make on a report page, from the facts measured in it; one line per
    failure (an empty list: the page passes)."""
    failures = []
    if facts["scroll_width"] > width:
        failures.append(f"page is {facts['scroll_width']} px wide at a {width} px window (sideways scroll)")
    if not facts["images"]:
        failures.append("no figures in the page")
    failures += [f"figure {i['alt']!r} did not load" for i in facts["images"] if not i["width"] > 0]
    bad = sorted({c for c in facts["cells"] if c.lower() in BAD_CELLS})
    if bad:
        failures.append("table cells read " + ", ".join(repr(c) for c in bad))
    if not any(h in facts["headers"] for h in ACCURACY_HEADERS):
        failures.append("no accuracy (ATE) or relations table")
    return failures


def _above(fd: int, low: int) -> int:
    """``fd`` moved to a descriptor number of at least ``low``."""
    moved = fcntl.fcntl(fd, fcntl.F_DUPFD_CLOEXEC, low)
    os.close(fd)
    return moved


class Browser:
    """A headless Chromium driven over the DevTools protocol on a pipe (fd 3 in, fd 4 out; each
    message JSON followed by a NUL byte)."""

    def __init__(self, exe: str):
        self.profile = tempfile.mkdtemp(prefix="report_shots_")
        to_child, self._w = os.pipe()
        self._r, from_child = os.pipe()
        # the child's ends above 4, so that placing them at 3 and 4 cannot overwrite one with the other
        to_child, from_child = (_above(fd, 10) for fd in (to_child, from_child))
        args = [exe, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", "--no-first-run",
                f"--user-data-dir={self.profile}", "--remote-debugging-pipe", "about:blank"]  # fmt: skip
        self.proc = subprocess.Popen(
            args,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            pass_fds=(3, 4),
            preexec_fn=lambda: (os.dup2(to_child, 3), os.dup2(from_child, 4)),
        )
        os.close(to_child)
        os.close(from_child)
        self._buf = b""
        self._id = 0

    def _read(self) -> dict:
        while b"\0" not in self._buf:
            chunk = os.read(self._r, 1 << 20)
            if not chunk:
                raise RuntimeError("chromium closed the DevTools pipe")
            self._buf += chunk
        msg, self._buf = self._buf.split(b"\0", 1)
        return json.loads(msg)

    def send(self, method: str, session: str | None = None, **params) -> dict:
        """One command; its result (events read meanwhile are dropped)."""
        self._id += 1
        msg = {"id": self._id, "method": method, "params": params}
        if session:
            msg["sessionId"] = session
        os.write(self._w, json.dumps(msg).encode() + b"\0")
        while True:
            reply = self._read()
            if reply.get("id") == self._id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply["result"]

    def wait_event(self, method: str) -> dict:
        while (msg := self._read()).get("method") != method:
            pass
        return msg

    def close(self) -> None:
        try:
            self.send("Browser.close")
        finally:
            self.proc.wait(timeout=30)
            os.close(self._r)
            os.close(self._w)
            shutil.rmtree(self.profile, ignore_errors=True)


def shoot(browser: Browser, page: Path, png: Path) -> dict:
    """Open ``page`` at WIDTH px, measure it (MEASURE) and capture it full-page into ``png``."""
    target = browser.send("Target.createTarget", url="about:blank")["targetId"]
    session = browser.send("Target.attachToTarget", targetId=target, flatten=True)["sessionId"]
    browser.send("Emulation.setDeviceMetricsOverride", session, width=WIDTH, height=900,
                 deviceScaleFactor=1, mobile=False)  # fmt: skip
    browser.send("Page.enable", session)
    browser.send("Page.navigate", session, url=page.resolve().as_uri())
    browser.wait_event("Page.loadEventFired")
    measured = browser.send("Runtime.evaluate", session, expression=MEASURE, returnByValue=True)
    facts = measured["result"]["value"]
    width, height = max(WIDTH, facts["scroll_width"]), facts["page_height"]
    clip = {"x": 0, "y": 0, "width": width, "height": height, "scale": 1}
    shot = browser.send(
        "Page.captureScreenshot", session, format="png", captureBeyondViewport=True, clip=clip
    )
    png.write_bytes(base64.b64decode(shot["data"]))
    browser.send("Target.closeTarget", targetId=target)
    return facts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, default=default_data(), help="the real-log folder (real_logs.py)")
    ap.add_argument("--work", type=Path, default=Path(tempfile.gettempdir()) / "cornerslam_report_shots")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "report_shots")
    ap.add_argument("--chromium", default=shutil.which("chromium") or shutil.which("chromium-browser"))
    ap.add_argument("--reuse", action="store_true", help="keep a report.html already in --work")
    args = ap.parse_args()
    if not args.chromium:
        raise SystemExit("error: no chromium on PATH (apt-get install chromium, or pass --chromium PATH)")
    logs = {
        "sim_office": ROOT / "sample_logs" / "sim_office.mcap",
        "infinite_corridor": args.data / "radish" / "infinite-corridor.log",
    }
    for log in logs.values():
        if not log.is_file():
            raise SystemExit(f"error: {log} not found (pass --data, the real-log folder)")
    reports = {name: run_report(name, log, args.work, args.reuse) for name, log in logs.items()}
    args.out.mkdir(parents=True, exist_ok=True)
    browser = Browser(args.chromium)
    checks = {}
    try:
        for name, page in reports.items():
            facts = shoot(browser, page, args.out / f"{name}.png")
            failures = verdict(facts)
            checks[name] = {
                "log": logs[name].name,
                "scroll_width": facts["scroll_width"],
                "page_height": facts["page_height"],
                "images": len(facts["images"]),
                "images_loaded": sum(i["width"] > 0 for i in facts["images"]),
                "table_cells": len(facts["cells"]),
                "failures": failures,
            }
            print(f"{name}: {'ok' if not failures else '; '.join(failures)} -> {args.out / (name + '.png')}")
    finally:
        browser.close()
    (args.out / "checks.json").write_text(json.dumps(checks, indent=2) + "\n")
    sys.exit(1 if any(c["failures"] for c in checks.values()) else 0)


if __name__ == "__main__":
    main()
