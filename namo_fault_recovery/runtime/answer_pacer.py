"""
Service answers released a few at a time, so that a burst of callers gets every answer.

Free of ROS.  When a library is published, every caller waiting for it is answered at
once.  With rmw_fastrtps every client of a service receives every response on the
service's response topic and keeps only its last few (the client's QoS depth, 10 by
default), so a burst of 50 responses sent in one instant overflows the clients' history
and some lose their own answer (measured: 16-21 of 50 answered).  The pacer releases at
most ``batch`` answers every ``gap`` seconds, which keeps default clients well inside
their depth while adding only ``gap * callers / batch`` to the last answer (0.1 s for 50).
"""

from collections import deque
import threading
import time


class AnswerPacer:
    """A thread that calls queued ``release()`` callables, ``batch`` every ``gap`` s."""

    def __init__(self, wake, batch=4, gap=0.008):
        self._wake = wake                  # called after each batch (wakes the executor)
        self._batch = batch
        self._gap = gap
        self._queue = deque()
        self._cond = threading.Condition()
        self._stopping = False
        self._thread = threading.Thread(target=self._loop, name='answers', daemon=True)

    def start(self):
        """Start the thread."""
        self._thread.start()

    def submit(self, release):
        """Queue one answer (a callable that completes the caller's future)."""
        with self._cond:
            if self._stopping:
                release()
                return
            self._queue.append(release)
            self._cond.notify()

    def _loop(self):
        while True:
            with self._cond:
                while not self._queue and not self._stopping:
                    self._cond.wait()
                batch = [self._queue.popleft()
                         for _ in range(min(self._batch, len(self._queue)))]
                more = bool(self._queue)
                stopping = self._stopping and not batch
            if stopping:
                return
            for release in batch:
                release()
            self._wake()
            if more:
                time.sleep(self._gap)

    def stop(self):
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
