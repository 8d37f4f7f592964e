"""
Service answers sent one at a time, paced, so that every caller of a burst gets its own.

Free of ROS.  With rmw_fastrtps every client of a service receives every response on the
service's one response topic and keeps only its last few unread: the client's QoS depth,
10 in ``rmw_qos_profile_services_default`` (what ``ros2 service call`` and most clients
use).  A client drops the responses meant for others only as it takes them, one per
wait of its executor, so when many answers go out together a client's reader overflows
and may lose its own (measured: 28 of 50 default clients answered, 13 of 20 calls of one
client, with four answers released every 8 ms, the node's executor bunching them).

The pacer bounds what any reader can find unread:

- answers are released one at a time, the next only once the previous was sent (the
  node's executor sends an answer when its callback returns; :meth:`AnswerPacer.sent`
  is called just before), so a busy executor cannot bunch them;
- a token bucket (:class:`Bucket`) lets ``burst`` answers go at once, then one per
  ``gap`` seconds.

In any L seconds at most ``burst + 1 + L / gap`` answers go out, so a reader that takes a
sample per ``gap`` never holds more than ``burst + 1`` (5: half the default depth).  A lone
caller is answered at once; 50 callers together within about ``50 * gap`` seconds
(1.5 s; with 10 ms one crowd of 50 in 7 lost answers while the machine was busy).
"""

from collections import deque
import threading
import time
from typing import Callable

BURST = 4             # answers sent back to back after a quiet moment
GAP = 0.025           # s per answer after that: slower than a busy reader of 50 clients takes
SENT_TIMEOUT = 0.5    # s: a released answer not reported sent by then no longer holds others
_EPSILON = 1e-9       # of a token: rounding of the refill


class Bucket:
    """A token bucket: ``burst`` tokens, refilled at one per ``gap`` seconds."""

    def __init__(self, burst: int = BURST, gap: float = GAP):
        self._burst = burst
        self._gap = gap
        self._tokens = float(burst)
        self._at = None

    def wait(self, now: float) -> float:
        """Return how long to wait from ``now`` for a token (0: one is there)."""
        self._refill(now)
        missing = 1.0 - self._tokens
        return 0.0 if missing <= _EPSILON else missing * self._gap

    def take(self, now: float) -> None:
        """Spend a token at ``now`` (one must be there: :meth:`wait` returned 0)."""
        self._refill(now)
        self._tokens -= 1.0

    def _refill(self, now):
        if self._at is not None:
            self._tokens = min(float(self._burst), self._tokens + (now - self._at) / self._gap)
        self._at = now


class AnswerPacer:
    """A thread that calls queued ``release()`` callables one at a time, paced."""

    def __init__(self, wake: Callable[[], None], burst: int = BURST, gap: float = GAP,
                 sent_timeout: float = SENT_TIMEOUT):
        self._wake = wake                  # called after each release (wakes the executor)
        self._bucket = Bucket(burst, gap)
        self._sent_timeout = sent_timeout
        self._queue = deque()
        self._unsent = False               # an answer released, not yet reported sent
        self._cond = threading.Condition()
        self._stopping = False
        self._thread = threading.Thread(target=self._loop, name='answers', daemon=True)

    def start(self) -> None:
        """Start the thread."""
        self._thread.start()

    def submit(self, release: Callable[[], None]) -> None:
        """Queue one answer (a callable that completes the caller's future)."""
        with self._cond:
            if self._stopping:
                release()
                return
            self._queue.append(release)
            self._cond.notify()

    def sent(self) -> None:
        """Say that the answer released last is being sent: the next one may follow."""
        with self._cond:
            self._unsent = False
            self._cond.notify()

    def _next(self):
        """Return the next release once its turn came (None when stopping)."""
        with self._cond:
            while True:
                if self._stopping:
                    return None
                if not self._queue:
                    self._cond.wait()
                    continue
                delay = self._bucket.wait(time.monotonic())
                if delay > 0.0:
                    self._cond.wait(delay)
                    continue
                self._bucket.take(time.monotonic())
                self._unsent = True
                return self._queue.popleft()

    def _loop(self):
        while True:
            release = self._next()
            if release is None:
                return
            release()
            self._wake()
            with self._cond:          # a lost report holds the others only so long
                self._cond.wait_for(lambda: not self._unsent or self._stopping,
                                    self._sent_timeout)
                self._unsent = False

    def stop(self) -> None:
        """Answer everything still queued at once, then stop the thread."""
        with self._cond:
            self._stopping = True
            rest = list(self._queue)
            self._queue.clear()
            self._cond.notify_all()
        for release in rest:
            release()
        if rest:
            self._wake()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
