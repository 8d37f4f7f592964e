"""Two test sessions on one host never get the same ROS domains (node_harness slots)."""

import os
import subprocess
import sys

from node_harness import ROOT, session_domain, session_slot, SLOTS, stress_domain


def _other_session_slot(env):
    # The child draws as if it had this session's pid: a pid-derived slot would collide.
    code = (f'import os; os.getpid = lambda: {os.getpid()}\n'
            'from node_harness import session_slot; print(session_slot())')
    out = subprocess.run([sys.executable, '-c', code], cwd=ROOT / 'test', env=env,
                         capture_output=True, text=True, timeout=60, check=True)
    return int(out.stdout.split()[-1])


def test_a_concurrent_session_takes_another_slot_and_so_other_domains():
    mine = session_slot()
    assert 0 <= mine < SLOTS and session_slot() == mine          # held, not re-drawn
    assert session_domain(0) == 1 + 5 * mine and stress_domain(0) == 102 + 5 * mine
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(ROOT), str(ROOT / 'test'), os.environ.get('PYTHONPATH', '')]))
    env.pop('NAMO_TEST_DOMAIN_BASE', None)
    others = {_other_session_slot(env) for _ in range(2)}
    # Each child starts its search at this session's slot, finds it held and takes the
    # next free one (held only while the child runs: both children may take the same).
    assert mine not in others


def test_a_benchmarks_private_node_never_takes_a_test_domain(monkeypatch):
    # Every domain a test session can use (all slots: modules, stress tests, exploration)
    # against every domain a private node (benchmarks, demos) can draw.
    from namo_fault_recovery.runtime import private_node
    tests = set()
    for slot in range(SLOTS):
        tests |= {1 + 5 * slot + k for k in range(5)} | {102 + 5 * slot + k for k in range(5)}
        tests.add(202 + slot)
    drawn = set()
    for pid in range(1000, 1100):
        monkeypatch.setattr(private_node.os, 'getpid', lambda pid=pid: pid)
        drawn.add(private_node.private_domain())
    assert drawn and max(drawn) <= 232 and not drawn & tests, sorted(drawn & tests)
