"""Messages put back in stamp order (:func:`in_stamp_order`) before they are synchronised (sync.py): a bag
holds them in the order they were received, which is not always their stamps' order."""

from __future__ import annotations

import heapq
import logging
import math
from collections.abc import Iterable, Iterator

from ..types import OdomSample, Scan

log = logging.getLogger(__name__)

# s: a message logged up to this far behind the newest before it is put back in stamp order, holding at
# most REORDER_MAX messages
REORDER_WINDOW = 1.0
REORDER_MAX = 1000


def in_stamp_order(
    messages: Iterable[Scan | OdomSample], window: float = REORDER_WINDOW
) -> Iterator[Scan | OdomSample]:
    """The messages in the order of their stamps where one came up to ``window`` seconds behind the newest
    before it: a bag is in the order messages were received, and a scan received a little late (a busy
    driver, a network hop) came behind a later one and was skipped as going backwards (a ROS-user probe:
    5 % of neighbouring scans swapped lost 25 scans). A message is passed on once one stamped ``window``
    after it has come, of either kind (one kind's last messages do not wait for the log's end, nor for a
    slower kind), or when REORDER_MAX wait. One farther behind is no late arrival but a clock that went
    back (or a stamp far ahead before it): those waiting are passed on, then it, in the log's order, as
    synchronise has always judged them. Equal stamps keep the log's order; a stamp that is not finite is
    passed on as it comes."""
    heap: list = []
    newest, seq, moved, kind_newest = -math.inf, 0, [0, 0], [-math.inf, -math.inf]
    for msg in messages:
        if not math.isfinite(msg.stamp):
            yield msg
            continue
        if msg.stamp < newest - window:
            while heap:
                yield heapq.heappop(heap)[2]
            yield msg
            continue
        kind = 0 if isinstance(msg, Scan) else 1
        moved[kind] += msg.stamp < kind_newest[kind]  # (behind one of its kind: a scan among samples is not)
        kind_newest[kind], newest = max(kind_newest[kind], msg.stamp), max(newest, msg.stamp)
        heapq.heappush(heap, (msg.stamp, seq, msg))
        seq += 1
        while heap and (heap[0][0] <= newest - window or len(heap) > REORDER_MAX):
            yield heapq.heappop(heap)[2]
    while heap:
        yield heapq.heappop(heap)[2]
    if any(moved):
        log.info("%d scans and %d odometry samples came out of stamp order in the log: put in order", *moved)
