"""Scan/odometry synchronisation (keyframe selection: keyframes.py).

``synchronise(messages)`` turns the time-ordered stream of :class:`Scan` and :class:`OdomSample`
from a log reader into :class:`Synced` pairs (scan, odometry pose), the odometry interpolated at the
scan's stamp, each flagged when the odometry jumped since the previous pair (``reanchor_odometry``).
It streams in bounded memory: a scan waits for an odometry sample at or after its stamp for at most
:data:`MAX_GAP` seconds of later scans (and :data:`MAX_PENDING` scans), and only the odometry
samples that a later scan may still need are kept (at most :data:`MAX_ODOM`).

Interpolation between the two odometry samples that bracket a scan is linear in (x, y) and along the
shorter arc in θ (:func:`~cornerslam_cli.geometry.interpolate`).

Scans that cannot be interpolated are skipped and counted in :class:`SyncStats`: before the first or
after the last odometry sample, in a gap of the odometry (samples more than MAX_GAP apart around it),
stamps that go backwards or repeat. "Backwards" is relative to the last scan that could still be
paired: a scan more than MAX_GAP after the newest sample (one far-future stamp, 1e18; also one logged
before the first sample, checked when that sample comes) does not become the reference, so it cannot
make the later scans look late; it is judged again as each sample comes until the next scan (a sample
logged just after it, at its stamp, pairs with it), and else skipped.
Odometry samples that go back in time are dropped and counted too. One warning sums them up; when no
scan met the odometry and their stamps lie more than :data:`CLOCKS_APART` apart, it (and the run's
error) says they are on different clocks (:meth:`SyncStats.other_clocks`).
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np

from ..geometry import compose, interpolate, inverse, relative, wrap_angle
from ..types import OdomSample, Scan
from .deskew import velocity
from .params import OdomJumpConfig

log = logging.getLogger(__name__)

MAX_GAP = 30.0  # s: odometry this far apart does not bracket a scan; a scan waits this long for odometry
# s: scans and odometry whose stamps do not overlap and lie farther apart than this are on different clocks
# (simulated time from 0 against the wall clock, ~1.7e9 s; a header stamped in another time zone): one
# recording's topics run seconds apart at most, and the gaps the synchroniser skips are MAX_GAP
CLOCKS_APART = 3600.0
CLOCKS_HINT = (
    "check that the recording used one clock for both (use_sim_time in every node, or in none) and that "
    "the drivers fill the header stamps"
)
MAX_PENDING = 1000  # scans waiting for odometry at most
MAX_ODOM = 10_000  # odometry samples kept ahead of the scans at most
# s: a scan's velocity (deskewing: logs/deskew.py) is the odometry's mean over this long after its stamp —
# a 10 Hz laser's whole sweep, and several samples of a fast odometry, whose single steps are noisy
VELOCITY_WINDOW = 0.1


@dataclass(frozen=True)
class Synced:
    """A scan and the odometry pose at its stamp; ``odom_jump``: the odometry jumped (and was
    re-anchored, :func:`reanchor_odometry`) since the previous pair was yielded; ``twist``: the
    robot's velocity (vx, vy, ω; base frame, m/s and rad/s) during the laser's sweep, taken as the
    odometry's mean over the ``VELOCITY_WINDOW`` after the stamp (the SE(2) logarithm of the odometry's motion
    over it; zero when the odometry ends at the stamp or has a gap after it), what deskewing needs
    (logs/deskew.py)."""

    scan: Scan
    odom: np.ndarray
    odom_jump: bool = False
    twist: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass
class StampRange:
    """The earliest and latest stamp of a stream, seconds (``lo`` > ``hi``: none seen)."""

    lo: float = np.inf
    hi: float = -np.inf

    def see(self, t: float) -> None:
        self.lo, self.hi = min(self.lo, t), max(self.hi, t)

    def text(self) -> str:
        return f"{self.lo:.3f} to {self.hi:.3f} s"


@dataclass
class SyncStats:
    scans_in: int = 0
    scans_out: int = 0
    before_first_odom: int = 0
    after_last_odom: int = 0
    odom_gap: int = 0  # scans in a gap of the odometry: no sample within MAX_GAP (or MAX_PENDING scans)
    scan_time_backwards: int = 0
    odom_time_backwards: int = 0
    keyframes_skipped: int = 0
    odom_jumps: int = 0
    scan_stamps: StampRange = field(default_factory=StampRange)  # (not counts: not in as_dict)
    odom_stamps: StampRange = field(default_factory=StampRange)
    # each re-anchoring (reanchor_odometry): the stamp of the first sample it moved and F, corrected = F ∘
    # raw from there on (not counts: not in as_dict) — how the results MCAP gets the odometry as logged
    anchors: list[tuple[float, tuple[float, float, float]]] = field(default_factory=list)

    @property
    def scans_skipped(self) -> int:
        return self.before_first_odom + self.after_last_odom + self.odom_gap + self.scan_time_backwards

    def skipped_why(self) -> str:
        """The scans synchronise skipped, by why, only the kinds that happened ("" when none): "3 before the
        first and 2 after the last odometry sample, 198 in gaps of the odometry (…), 1 whose stamp went
        backwards or repeated"."""
        ends = [(self.before_first_odom, "before the first"), (self.after_last_odom, "after the last")]
        ends = [f"{n} {where}" for n, where in ends if n]
        parts = [" and ".join(ends) + " odometry sample"] if ends else []
        if self.odom_gap:
            parts.append(f"{self.odom_gap} in gaps of the odometry (no sample within {MAX_GAP:g} s)")
        if self.scan_time_backwards:
            parts.append(f"{self.scan_time_backwards} whose {_stamps(self.scan_time_backwards)}")
        return ", ".join(parts)

    def as_dict(self) -> dict:
        d = {k: v for k, v in self.__dict__.items() if not isinstance(v, (StampRange, list))}
        d["scans_skipped"] = self.scans_skipped
        return d

    def unstamped_scans(self) -> bool:
        """Whether two or more scans came and all had the same stamp (a driver that does not fill it)."""
        return self.scans_in >= 2 and self.scan_stamps.lo == self.scan_stamps.hi

    def other_clocks(self, receive: bool = False) -> str:
        """Why no scan met the odometry, when their stamps are on different clocks (their spans do not
        overlap and lie more than CLOCKS_APART apart), naming both spans; else "". ``receive``: the stamps
        are the recorder's times (``input.stamps``), not header stamps."""
        s, o = self.scan_stamps, self.odom_stamps
        apart = max(o.lo - s.hi, s.lo - o.hi)  # inf with either unseen
        if self.scans_out or not CLOCKS_APART < apart < np.inf:
            return ""
        if self.unstamped_scans():
            why = "the recorder gave them one time (a converted log?)" if receive else (
                "the laser driver does not fill the scans' header stamps"
            )  # fmt: skip
            return (
                f"every one of its {self.scans_in} scans is stamped {s.lo:.3f} s (the odometry {o.text()}): "
                + why
            )
        why = "their log times are on different clocks (two recordings merged?)" if receive else (
            "their stamps are on different clocks"
        )  # fmt: skip
        return f"the scans are stamped {s.text()} and the odometry {o.text()}, {apart:.4g} s apart: {why}"


def spans_apart(stats: SyncStats) -> str:
    """The scans' and the odometry's spans, when they do not overlap at all (a run that processed no scan
    says why: "501 before the first odometry sample" did not say the odometry was stamped 1000 s earlier,
    a probe); else ""."""
    s, o = stats.scan_stamps, stats.odom_stamps
    apart = max(o.lo - s.hi, s.lo - o.hi)
    if not 0.0 < apart < np.inf:
        return ""
    return f"the scans are stamped {s.text()} and the odometry {o.text()}, {apart:.4g} s apart"


def clocks_hint(stats: SyncStats) -> str:
    """What to check when :meth:`SyncStats.other_clocks` says why no scan met the odometry."""
    if stats.unstamped_scans():
        return "make the laser driver fill each scan's header stamp: it writes one stamp for all"
    return CLOCKS_HINT


def synchronise(
    messages: Iterable[Scan | OdomSample],
    stats: SyncStats | None = None,
    warn: Callable[..., None] = log.warning,
) -> Iterator[Synced]:
    """Yield a :class:`Synced` for every scan that lies within the odometry's time span; what is
    skipped is counted in ``stats`` and summed up in one call of ``warn`` at the end."""
    st = stats if stats is not None else SyncStats()
    odom: deque[OdomSample] = deque()  # samples a later scan may still need, increasing stamps
    pending: deque[Scan] = deque()  # scans waiting for an odometry sample at or after their stamp
    last_scan_stamp = -np.inf
    last_odom_stamp = -np.inf
    first_odom_stamp = np.inf
    waited_out = 0  # scans that waited too long since the last odometry sample
    # a scan more than MAX_GAP after the newest sample: judged again after each sample until the next
    # scan comes (then it has waited out) or the log ends (after the last sample)
    held: Scan | None = None
    # stamps of the odometry samples re-anchored across a jump since the last pair yielded: a pair carries
    # those up to the first sample at or after its stamp (the sample its interpolation ends at)
    jumps: deque[float] = deque()

    def emit_ready(last: bool = False) -> Iterator[Synced]:
        # a scan waits for the odometry up to VELOCITY_WINDOW after its stamp (its velocity; ``last``:
        # no more will come, what is there is all there will be)
        while (
            pending
            and odom
            and (
                odom[-1].stamp >= pending[0].stamp + VELOCITY_WINDOW
                or (last and odom[-1].stamp >= pending[0].stamp)
            )
        ):
            scan = pending.popleft()
            t = scan.stamp
            if t < odom[0].stamp:  # before all odometry, or before the samples still kept
                if t < first_odom_stamp:
                    st.before_first_odom += 1
                else:
                    st.odom_gap += 1
                continue
            # drop samples that no later scan can need: keep the last one at or before t
            while len(odom) >= 2 and odom[1].stamp <= t:
                odom.popleft()
            a = odom[0]
            b = odom[1] if len(odom) >= 2 else odom[0]
            if t > a.stamp and b.stamp - a.stamp > MAX_GAP:  # not interpolated across a gap
                st.odom_gap += 1
                continue
            st.scans_out += 1
            bracket = np.array([[a.x, a.y, a.theta], [b.x, b.y, b.theta]])
            pose = interpolate(np.array([a.stamp, b.stamp]), bracket, t)
            twist = _velocity(odom, t, pose) if b.stamp - a.stamp <= MAX_GAP else np.zeros(3)
            until = a.stamp if a.stamp == t else b.stamp
            jumped = bool(jumps) and jumps[0] <= until
            while jumps and jumps[0] <= until:
                jumps.popleft()
            yield Synced(scan, pose, jumped, twist)

    def on_scan(msg: Scan) -> Iterator[Synced]:
        nonlocal last_scan_stamp, waited_out, held
        if msg.stamp <= last_scan_stamp:
            st.scan_time_backwards += 1
            return
        if last_odom_stamp == -np.inf:  # no odometry yet: a bag's log order is not its stamps' order,
            last_scan_stamp = msg.stamp  # so it waits for the first sample (its stamp decides)
            pending.append(msg)
            while len(pending) > MAX_PENDING or msg.stamp - pending[0].stamp > MAX_GAP:
                pending.popleft()
                st.before_first_odom += 1
            return
        if msg.stamp - last_odom_stamp > MAX_GAP:
            # no odometry near it: it is held (not the reference for "backwards": one far-future stamp
            # would otherwise skip every later scan), judged again as samples come — the one logged just
            # after it, at its stamp (a CARMEN laser's pose fields, ODOM lines written after the laser's)
            held = msg
            return
        last_scan_stamp = msg.stamp
        pending.append(msg)
        while pending and (len(pending) > MAX_PENDING or msg.stamp - pending[0].stamp > MAX_GAP):
            # one waiting only for the rest of its velocity's window: synchronised with a shorter one
            if odom[-1].stamp >= pending[0].stamp:
                yield from emit_ready(last=True)
                continue
            pending.popleft()  # no odometry came for it: dropped now, counted when it is known why
            waited_out += 1

    for msg in messages:
        if isinstance(msg, Scan):
            st.scans_in += 1
            st.scan_stamps.see(msg.stamp)
            if held is not None:  # no sample near it came before this scan
                held, waited_out = None, waited_out + 1
            yield from on_scan(msg)
        elif isinstance(msg, OdomSample):
            st.odom_stamps.see(msg.stamp)
            if msg.stamp <= last_odom_stamp:
                st.odom_time_backwards += 1
                continue
            if msg.jumped:
                jumps.append(msg.stamp)
            last_odom_stamp = msg.stamp
            first_odom_stamp = min(first_odom_stamp, msg.stamp)
            st.odom_gap += waited_out  # odometry resumed after them
            waited_out = 0
            if first_odom_stamp == msg.stamp:  # the first sample: scans logged before it and stamped far
                while pending and pending[-1].stamp - msg.stamp > MAX_GAP:  # after it (1e18) are no
                    pending.pop()  # reference for "backwards" (they would make every later scan late)
                    waited_out += 1
                last_scan_stamp = pending[-1].stamp if pending else -np.inf
            odom.append(msg)
            if not pending:  # later scans come after last_scan_stamp: keep the last sample before it
                while len(odom) >= 2 and odom[1].stamp <= last_scan_stamp:
                    odom.popleft()
            if len(odom) > MAX_ODOM:
                odom.popleft()
            if held is not None:  # a sample came after it: it is judged again against this one
                scan, held = held, None
                yield from on_scan(scan)
        yield from emit_ready()
    yield from emit_ready(last=True)
    waited_out += held is not None
    if last_odom_stamp == -np.inf:  # no odometry at all: every scan was before it
        st.before_first_odom += len(pending)
    else:
        st.after_last_odom += len(pending) + waited_out
    _warn_skipped(st, warn)


def _velocity(odom: deque[OdomSample], t: float, pose: np.ndarray) -> np.ndarray:
    """The constant velocity (logs/deskew.py) that takes the robot from ``pose`` (the odometry at ``t``)
    to the odometry's pose VELOCITY_WINDOW later (or at its last sample, when it ends sooner); zero with
    no sample after ``t``."""
    end = min(t + VELOCITY_WINDOW, odom[-1].stamp)
    if end <= t:
        return np.zeros(3)
    near = []  # the samples up to the first at or after ``end`` (the deque may run far ahead)
    for o in odom:
        near.append(o)
        if o.stamp >= end:
            break
    stamps = np.array([o.stamp for o in near])
    poses = np.array([[o.x, o.y, o.theta] for o in near])
    return velocity(relative(pose, interpolate(stamps, poses, end)), end - t)


def _warn_skipped(st: SyncStats, warn: Callable[..., None]) -> None:
    """One warning summing up the scans and odometry samples that synchronise skipped — none when it kept no
    scan: the run then fails with an error that says the same (frontend.check_processed; the two lines
    said it twice, a probe)."""
    if not (st.scans_skipped or st.odom_time_backwards) or not st.scans_out:
        return
    scans = st.skipped_why()
    n_scans, n_odom = st.scans_skipped, st.odom_time_backwards
    said = [
        f"{n_scans} scan{'s' if n_scans != 1 else ''}: {scans}" if scans else "",
        f"{n_odom} odometry sample{'s' if n_odom != 1 else ''} whose {_stamps(n_odom)}" if n_odom else "",
    ]
    warn("skipped %s", "; ".join(s for s in said if s))  # (other clocks: the error, none kept)


def _stamps(n: int) -> str:
    return "stamp went backwards or repeated" if n == 1 else "stamps went backwards or repeated"


def reanchor_odometry(
    messages: Iterable[Scan | OdomSample],
    cfg: OdomJumpConfig,
    stats: SyncStats | None = None,
    warn: Callable[..., None] = log.warning,
) -> Iterator[Scan | OdomSample]:
    """The message stream with odometry jumps and resets taken out (``input.odom_jump``).

    A jump between consecutive odometry samples a, b (see :class:`OdomJumpConfig`) is not applied as
    motion: from b on, odometry is re-anchored so that b continues from a's pose, F ← (F ∘ a) ∘ b⁻¹
    with corrected = F ∘ raw. Marked ``jumped`` (the sample b), counted in ``stats.odom_jumps`` and
    warned; scans pass unchanged.
    Samples whose stamps do not increase pass through untouched (``synchronise`` drops them).
    """
    st = stats if stats is not None else SyncStats()
    if cfg.distance <= 0.0:
        yield from messages
        return
    fix = np.zeros(3)  # F: corrected = F ∘ raw
    prev: OdomSample | None = None
    scan_since = True  # a scan came since the last re-anchoring (else a new one replaces it in st.anchors)
    for msg in messages:
        scan_since = scan_since or isinstance(msg, Scan)
        if isinstance(msg, OdomSample):
            if prev is not None and msg.stamp <= prev.stamp:
                yield msg
                continue
            raw = np.array([msg.x, msg.y, msg.theta])
            jumped = False
            if prev is not None:
                a = np.array([prev.x, prev.y, prev.theta])
                scale = max(1.0, (msg.stamp - prev.stamp) / cfg.period)
                moved = float(np.hypot(*(raw[:2] - a[:2])))
                turned = abs(float(wrap_angle(raw[2] - a[2])))
                if moved > cfg.distance * scale or turned > cfg.angle * scale:
                    jumped = True
                    st.odom_jumps += 1
                    if st.odom_jumps <= 5:
                        warn(
                            "odometry jumped by %.2f m and %.1f° in %.3f s at %.3f s (reset?): "
                            "not applied as motion, odometry re-anchored",
                            moved, np.degrees(turned), msg.stamp - prev.stamp, msg.stamp,
                        )  # fmt: skip
                    fix = compose(compose(fix, a), inverse(raw))
                    if not scan_since:  # (no scan to place with the one before: as many as scans at most)
                        st.anchors.pop()
                    st.anchors.append((msg.stamp, tuple(float(v) for v in fix)))
                    scan_since = False
            prev = msg
            if st.odom_jumps:
                msg = OdomSample(msg.stamp, *(float(v) for v in compose(fix, raw)), jumped=jumped)
        yield msg
