"""
``thread_priority``: the node's own threads under SCHED_FIFO, its child processes not.

``runtime.realtime`` is exercised in a child interpreter (the test process keeps its
own scheduling), then on the real node: its threads run real-time, its engine process
under the normal scheduler; where the machine refuses real-time priority, the node says
why and runs on.  ``engine_nice``: the engine process computes a deadline run at that
nice value and refines at its own, or says why it cannot.
"""

import json
import os
from pathlib import Path
import subprocess
import sys
import time

from namo_fault_recovery.runtime import realtime
from node_harness import NodeProcess, session_domain
import pytest

DOMAIN = session_domain(1)       # the lifecycle tests': never at the same time

PROBE = r"""
import json, multiprocessing, os, threading
from namo_fault_recovery.runtime.realtime import leave_fifo, set_fifo_priority

def child(queue):
    leave_fifo()
    queue.put(os.sched_getscheduler(0))

if __name__ == '__main__':
    stop = threading.Event()
    before = threading.Thread(target=stop.wait)
    before.start()
    refused = set_fifo_priority(3)
    seen = {}
    after = threading.Thread(target=lambda: seen.update(after=os.sched_getscheduler(0)))
    after.start()
    after.join()
    ctx = multiprocessing.get_context('spawn')
    queue = ctx.Queue()
    proc = ctx.Process(target=child, args=(queue,))
    proc.start()
    seen['child'] = queue.get(timeout=60)
    proc.join()
    seen['threads'] = [os.sched_getscheduler(int(t)) for t in os.listdir('/proc/self/task')]
    stop.set()
    before.join()
    print(json.dumps({'refused': refused, **seen}))
"""


def test_zero_changes_nothing_and_out_of_range_is_refused():
    policy = os.sched_getscheduler(0)
    assert realtime.set_fifo_priority(0) is None
    assert os.sched_getscheduler(0) == policy
    with pytest.raises(ValueError, match='thread_priority: expected 0 .. 99, got 100'):
        realtime.set_fifo_priority(100)


def test_every_thread_then_new_threads_real_time_children_normal(tmp_path):
    probe = tmp_path / 'probe.py'          # a file: a spawned child imports its main
    probe.write_text(PROBE)
    out = subprocess.run([sys.executable, str(probe)], capture_output=True, text=True,
                         timeout=120, check=True).stdout
    seen = json.loads(out.strip().splitlines()[-1])
    assert seen['child'] == os.SCHED_OTHER           # leave_fifo in every child process
    if seen['refused'] is not None:                  # a machine without rtprio: said why
        assert 'RLIMIT_RTPRIO' in seen['refused'] or 'no real-time' in seen['refused']
        assert set(seen['threads']) == {os.SCHED_OTHER} and seen['after'] == os.SCHED_OTHER
        return
    assert set(seen['threads']) == {os.SCHED_FIFO}, seen   # those that existed, the new
    assert seen['after'] == os.SCHED_FIFO


def test_a_refusal_puts_the_changed_threads_back(monkeypatch):
    calls = []

    def setscheduler(tid, policy, param):
        calls.append((tid, policy))
        if policy == os.SCHED_FIFO and len(calls) > 1:
            raise PermissionError(1, 'Operation not permitted')
    monkeypatch.setattr(realtime, '_thread_ids', lambda: [11, 12, 13])
    monkeypatch.setattr(realtime.os, 'sched_setscheduler', setscheduler)
    reason = realtime.set_fifo_priority(40)
    assert reason.startswith('thread_priority: cannot use SCHED_FIFO priority 40 '
                             '(Operation not permitted)'), reason
    assert 'RLIMIT_RTPRIO' in reason and '\n' not in reason
    assert calls == [(11, os.SCHED_FIFO), (12, os.SCHED_FIFO), (11, os.SCHED_OTHER)]


NICE_PROBE = r"""
import json, os, resource
from namo_fault_recovery.runtime.realtime import set_nice

allowed = set_nice(-3)
seen = {'allowed': allowed, 'nice': os.getpriority(os.PRIO_PROCESS, 0)}
os.setpriority(os.PRIO_PROCESS, 0, 0)
resource.setrlimit(resource.RLIMIT_NICE, (0, 0))    # no allowance (lowering is allowed)
if os.getuid() == 0:                                 # root: be nobody, without CAP_SYS_NICE
    os.setgid(65534)
    os.setuid(65534)
seen['refused'] = set_nice(-3)
seen['after'] = os.getpriority(os.PRIO_PROCESS, 0)
print(json.dumps(seen))
"""


def test_set_nice_lowers_the_value_or_says_which_limit_to_raise():
    out = subprocess.run([sys.executable, '-c', NICE_PROBE], capture_output=True, text=True,
                         timeout=60, check=True).stdout
    seen = json.loads(out.strip().splitlines()[-1])
    if seen['allowed'] is None:                 # root or an allowance: done
        assert seen['nice'] == -3
    refused = seen['refused']
    assert refused.startswith('engine_nice: cannot compute at nice -3 ('), refused
    assert 'RLIMIT_NICE' in refused and 'limits.conf' in refused and '\n' not in refused
    assert seen['after'] == 0
    with pytest.raises(ValueError, match='engine_nice: expected -20 .. 19, got 20'):
        realtime.set_nice(20)


@pytest.mark.slow
def test_the_engine_computes_a_deadline_run_at_its_nice_and_refines_at_its_own():
    from namo_fault_recovery.recovery.settings import RecoverySettings
    from namo_fault_recovery.runtime.engine_process import EngineProcess
    base = os.getpriority(os.PRIO_PROCESS, 0)
    engine = EngineProcess(nice=base - 2)
    engine.start()
    try:
        engine.wait_ready(timeout=120)
        assert os.getpriority(os.PRIO_PROCESS, engine.pid) == base     # warmed up at its own
        settings = RecoverySettings(deadline_sec=0.3)
        result, _ = engine.run(1, {'right_arm_joint4': None}, settings, 0, time.monotonic(),
                               None)
        run_nice = os.getpriority(os.PRIO_PROCESS, engine.pid)
        if engine.nice_refused is None:
            assert run_nice == base - 2
        else:                                       # not permitted here: said, and runs on
            assert 'engine_nice: cannot compute at nice' in engine.nice_refused
            assert run_nice == base
        engine.refine(2, result, settings, 0.2, lambda better: None)
        assert os.getpriority(os.PRIO_PROCESS, engine.pid) == base
    finally:
        engine.stop()


def _said(process, lines, timeout=120.0):
    """Wait until ``process`` wrote one of ``lines`` (once built, before it spins)."""
    end = time.monotonic() + timeout
    while True:
        text = process.stdout + process.stderr
        if any(line in text for line in lines):
            return text
        assert process.alive() and time.monotonic() < end, process.describe()
        time.sleep(0.1)


def _policies(pid):
    """Return {thread id: policy} of process ``pid``."""
    tasks = Path(f'/proc/{pid}/task')
    return {int(t.name): os.sched_getscheduler(int(t.name)) for t in tasks.iterdir()}


@pytest.mark.slow
def test_node_threads_real_time_engine_process_normal(tmp_path):
    node = NodeProcess(DOMAIN, state_dir=tmp_path / 'state',
                       args=['-p', 'thread_priority:=7', '-p', 'contingency_table:=false'])
    try:
        text = _said(node, ('threads under SCHED_FIFO, priority 7',
                            'cannot use SCHED_FIFO priority 7'))
        children = [int(p) for p in Path(f'/proc/{node.proc.pid}/task/{node.proc.pid}/'
                                         'children').read_text().split()]
        assert children, 'the engine process is a child of the node'
        assert all(os.sched_getscheduler(c) == os.SCHED_OTHER for c in children)
        if 'cannot use SCHED_FIFO priority 7' in text:     # refused: said, and runs on
            assert set(_policies(node.proc.pid).values()) == {os.SCHED_OTHER}
            return
        assert 'threads under SCHED_FIFO, priority 7' in text, node.describe()
        policies = _policies(node.proc.pid)
        assert policies[node.proc.pid] == os.SCHED_FIFO
        assert os.sched_getparam(node.proc.pid).sched_priority == 7
        fifo = sum(p == os.SCHED_FIFO for p in policies.values())
        assert fifo >= len(policies) - 2, policies     # the middleware's, Python's
    finally:
        assert node.stop() == 0, node.describe()


@pytest.mark.slow
def test_player_takes_the_same_parameter(tmp_path):
    from namo_fault_recovery.runtime.private_node import player_command
    player = NodeProcess(DOMAIN, args=['-p', 'thread_priority:=6'], command=player_command())
    try:
        said = ('threads under SCHED_FIFO, priority 6', 'cannot use SCHED_FIFO priority 6')
        _said(player, said)
        fifo = os.sched_getscheduler(player.proc.pid) == os.SCHED_FIFO
        assert fifo == (said[0] in player.stdout + player.stderr), player.describe()
    finally:
        assert player.stop() == 0, player.describe()
