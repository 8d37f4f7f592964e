"""Fast unit tests of the log rate limit (a fake clock: no test waits for real time)."""

import re

from namo_fault_recovery.runtime.log_throttle import LogThrottle
import pytest

SUPPRESSED = re.compile(r'\((\d+) more suppressed in the last (\d+\.\d) s\)$')


class FakeClock:
    """A monotonic clock the test moves by hand."""

    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def counted(lines):
    """Return how many events ``lines`` stand for: each line one, plus its suppressed."""
    total = 0
    for line in lines:
        match = SUPPRESSED.search(line)
        total += 1 + (int(match.group(1)) if match else 0)
    return total


def test_a_flood_of_1000_over_2_6_s_writes_at_most_3_lines_and_counts_every_event():
    clock = FakeClock()
    throttle = LogThrottle(1.0, clock)
    lines, times = [], []
    for i in range(1000):
        clock.now = 100.0 + 2.6 * i / 999
        line = throttle.admit('/joint_states', f'rejected /joint_states: NaN #{i}')
        flushed = throttle.flush()       # the node's tick flushes during the flood too
        for new in ([line] if line is not None else []) + flushed:
            lines.append(new)
            times.append(clock.now)
    assert len(lines) <= 3, lines
    assert lines[0] == 'rejected /joint_states: NaN #0'
    assert all(SUPPRESSED.search(line) for line in lines[1:]), lines
    assert all(b - a >= 1.0 for a, b in zip(times, times[1:])), times
    assert throttle.pending() == 1000 - counted(lines) > 0
    # After the flood the tick reports the rest once their second is over, not before.
    clock.now = times[-1] + 0.99
    assert throttle.flush() == []
    clock.now = times[-1] + 1.0
    last = throttle.flush()
    assert len(last) == 1 and last[0].startswith('rejected /joint_states: NaN #999 ('), last
    assert counted(lines + last) == 1000 and throttle.pending() == 0
    assert throttle.flush() == []


def test_the_count_names_the_span_since_the_previous_line():
    clock = FakeClock()
    throttle = LogThrottle(1.0, clock)
    assert throttle.admit('k', 'a') == 'a'
    clock.now += 0.3
    assert throttle.admit('k', 'b') is None
    clock.now += 0.4
    assert throttle.admit('k', 'c') is None
    clock.now += 0.6
    assert throttle.admit('k', 'd') == 'd (2 more suppressed in the last 1.3 s)'
    clock.now += 1.0
    assert throttle.admit('k', 'e') == 'e'       # nothing held back: no count


def test_each_kind_of_input_has_its_own_period():
    clock = FakeClock()
    throttle = LogThrottle(1.0, clock)
    assert throttle.admit('/joint_states', 'j1') == 'j1'
    assert throttle.admit('/actuator_fault', 'f1') == 'f1'
    assert throttle.admit('/joint_states', 'j2') is None
    assert throttle.admit('/actuator_fault', 'f2') is None
    clock.now += 0.5
    assert throttle.admit('/joint_states', 'j3') is None
    clock.now += 0.5
    assert sorted(throttle.flush()) == ['f2', 'j3 (1 more suppressed in the last 1.0 s)']
    assert throttle.pending() == 0


def test_a_period_must_be_positive():
    with pytest.raises(ValueError, match='period > 0'):
        LogThrottle(0.0)
