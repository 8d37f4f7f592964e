"""
A thread that runs a job on the newest item given to it, a moment later, off hot paths.

Free of ROS.  The node draws a library's RViz markers (forward kinematics of every
gesture and a few hundred ``Marker`` messages: milliseconds of Python) after each
publication.  Started as a new thread at the moment of publication, the drawing and the
thread's own start held the interpreter lock just when the service answers, the
diagnostics and the next run needed it.  :class:`LatestWorker` is one long-lived thread:
:meth:`~LatestWorker.submit` only stores the item (O(1)), and the job runs ``delay``
seconds later on the newest item; items submitted meanwhile collapse into the newest.
While ``hold()`` is true (the node handles a fault: a table hit is published within
milliseconds) the job waits, a ``delay`` at a time: drawn in the middle of a fault's
path, it held the interpreter lock that the intake and the publication needed.
"""

import threading
import time


class LatestWorker:
    """One thread that calls ``job(*item)`` on the newest submitted item, after ``delay``."""

    def __init__(self, job, delay=0.05, name='latest-worker', hold=lambda: False):
        self._job = job
        self._delay = delay
        self._hold = hold                  # hold() true: not now (checked every delay)
        self._cond = threading.Condition()
        self._item = None
        self._stopping = False
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)

    def start(self):
        """Start the thread (items submitted before are kept)."""
        self._thread.start()

    def submit(self, *item):
        """Keep ``item`` as the newest (replacing any not yet taken); never blocks long."""
        with self._cond:
            self._item = item
            self._cond.notify()

    def _loop(self):
        while True:
            with self._cond:
                while self._item is None and not self._stopping:
                    self._cond.wait()
                if self._stopping:
                    return
            time.sleep(self._delay)            # let the publication's followers run first
            while self._hold() and not self._stopping:
                time.sleep(self._delay)
            with self._cond:
                item, self._item = self._item, None
            if item is not None:
                self._job(*item)

    def stop(self, timeout=2.0):
        """Stop the thread; an item not yet taken is dropped."""
        with self._cond:
            self._stopping = True
            self._cond.notify_all()
        if self._thread.is_alive():
            self._thread.join(timeout)
