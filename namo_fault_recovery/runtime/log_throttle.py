"""
Rate limit for repeated log lines: at most one line per kind and period, none lost.

Free of ROS.  A flood of bad input (e.g. NaN ``/joint_states`` at 500 Hz) must not flood
the log too, yet a person reading the log must still learn how many inputs were
rejected.  :class:`LogThrottle` lets one line per key (a kind of input) through per
``period`` seconds of a monotonic clock; the ones held back are counted, and the next
line of that key says how many, e.g. ``(37 more suppressed in the last 1.0 s)``.  When
the flood stops, :meth:`LogThrottle.flush` (called from a periodic tick) returns the
count still pending once its period is over, so the lines' counts always add up to
every event.  The node's ``/diagnostics`` counters are kept apart and stay exact::

    throttle = LogThrottle(period=1.0)
    line = throttle.admit('/joint_states', 'rejected /joint_states: NaN')
    if line is not None:
        logger.warning(line)
    for line in throttle.flush():       # e.g. at 10 Hz
        logger.warning(line)
"""

from dataclasses import dataclass
import threading
import time
from typing import Callable, List, Optional

DEFAULT_PERIOD = 1.0       # s: at most one line per kind of event in this span


@dataclass
class _Kind:
    """What the throttle knows of one key."""

    last_line: float           # clock time of the last line let through
    suppressed: int = 0        # events held back since that line
    last_text: str = ''        # the newest held-back event's text


def suppressed_text(count: int, since: float) -> str:
    """Return the suffix that counts ``count`` events held back over ``since`` seconds."""
    return f'({count} more suppressed in the last {since:.1f} s)'


class LogThrottle:
    """At most one line per key and ``period`` s; the next line counts those held back."""

    def __init__(self, period: float = DEFAULT_PERIOD,
                 clock: Callable[[], float] = time.monotonic):
        if not period > 0:
            raise ValueError(f'LogThrottle: expected a period > 0 s, got {period!r}')
        self.period = float(period)
        self._clock = clock            # monotonic seconds (a fake one in the tests)
        self._lock = threading.Lock()
        self._kinds = {}               # key -> _Kind

    def admit(self, key: str, text: str) -> Optional[str]:
        """
        Return the line to log for one event of ``key`` now, or None to hold it back.

        A line let through after held-back events ends with their count and the span
        since the previous line of ``key``.
        """
        now = self._clock()
        with self._lock:
            kind = self._kinds.get(key)
            if kind is None:
                self._kinds[key] = _Kind(now)
                return text
            if now - kind.last_line < self.period:
                kind.suppressed += 1
                kind.last_text = text
                return None
            line = text
            if kind.suppressed:
                line = f'{text} {suppressed_text(kind.suppressed, now - kind.last_line)}'
            kind.last_line, kind.suppressed = now, 0
            return line

    def flush(self) -> List[str]:
        """
        Return a line per key whose held-back events are due (their period is over).

        Each line is the newest held-back event's text, with the count of the others;
        the key's period starts again, so a flood that resumes still gets one line per
        period.
        """
        now = self._clock()
        lines = []
        with self._lock:
            for kind in self._kinds.values():
                if kind.suppressed and now - kind.last_line >= self.period:
                    more = kind.suppressed - 1      # the line itself stands for one
                    lines.append(kind.last_text if not more else
                                 f'{kind.last_text} '
                                 f'{suppressed_text(more, now - kind.last_line)}')
                    kind.last_line, kind.suppressed = now, 0
        return lines

    def pending(self) -> int:
        """Return how many events are held back and not yet counted in a line."""
        with self._lock:
            return sum(kind.suppressed for kind in self._kinds.values())
