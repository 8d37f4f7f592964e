"""
The contingency table and the anytime refinement of the real ``recovery_node`` over DDS.

Covers: a fault in the table is answered from it (``library_origin: table``); a restart
reuses the table kept in ``state_dir``; a changed setting invalidates it (the next fault
is searched live, and a new table is built); a miss is published at the deadline, then a
better library arrives as a new version (``library_origin: refined``).
"""

import json
from pathlib import Path
import re
import time

from node_harness import NodeProcess, RosClient, session_domain, statuses_values
import pytest

pytestmark = pytest.mark.slow

DOMAIN = session_domain(2)      # modules run one after the other: the ids are reused
SINGLE_FAULTS = 14


@pytest.fixture
def client():
    client = RosClient(DOMAIN)
    yield client
    client.close()


def table_entries(state):
    """Return the number of entries of the table file in ``state`` (0 if none yet)."""
    try:
        return len(json.loads((Path(state) / 'contingency_table.json').read_text())['entries'])
    except (OSError, ValueError, KeyError):
        return 0


def wait_table(node, state, entries, timeout=180.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if table_entries(state) >= entries:
            return
        assert node.alive(), node.describe()
        time.sleep(0.2)
    pytest.fail(f'the table did not reach {entries} entries in {timeout:.0f} s; '
                f'{table_entries(state)} so far\n{node.describe()}')


def version_after_fault(client, joints, positions=()):
    """Publish a fault; return the diagnostics values of the library published for it."""
    before = client.latest().stamp
    since = client.diag_count()
    client.publish_fault(joints, positions)
    client.wait_library(after=before, what=f'the library for {joints}')

    def published(statuses):
        values = statuses_values(statuses['reconfiguration'])
        return values.get('up_to_date') == 'true' and values.get('library_origin') != \
            'reference'
    statuses = client.wait_diag(published, since=since, what='the library for the fault')
    return statuses_values(statuses['reconfiguration'])


def test_table_hit_then_restart_reuses_then_a_setting_invalidates(tmp_path, client):
    state = tmp_path / 'state'
    node = NodeProcess(DOMAIN, state_dir=state, args=['-p', 'refine_budget_sec:=0.0'])
    try:
        client.wait_library(what='the reference library')
        wait_table(node, state, SINGLE_FAULTS)
        # /diagnostics says so: every single fault is served at once.
        client.wait_diag(lambda s: 'contingency_table' in s and statuses_values(
            s['contingency_table']) == {'table_state': 'complete',
                                        'table_entries': str(SINGLE_FAULTS),
                                        'table_missing': '0'}, what='the table complete')
        values = version_after_fault(client, ['right_arm_joint2'])
        assert values['library_origin'] == 'table', values
        assert 'from the contingency table' in client.trigger('/reconfigure_gestures').message
        assert client.trigger('/clear_faults').success
    finally:
        assert node.stop() == 0, node.describe()
    assert 'contingency table: building 14 entries' in node.stderr, node.describe()

    # A restart with the same settings reuses the table: nothing is rebuilt.
    node = NodeProcess(DOMAIN, state_dir=state, args=['-p', 'refine_budget_sec:=0.0'])
    try:
        client.wait_library(lambda v: True, after=client.latest().stamp,
                            what="the restarted node's library")
        node.wait_output(f'contingency table: {SINGLE_FAULTS}', timeout=30.0)
        values = version_after_fault(client, ['right_arm_joint5'])
        assert values['library_origin'] == 'table', values
        assert client.trigger('/clear_faults').success
        assert 'reused from' in node.stderr and 'building 14 entries' not in node.stderr, \
            node.describe()

        # A setting that changes the result makes the table unusable: the next fault
        # is searched live, and a new table is built for the new settings (of every
        # single fault, or of the faults on top of the one now active if that fault came
        # first: the builder takes the newest plan).
        results = client.set_parameters(continuity_weight=0.02)
        assert all(r.successful for r in results), results
        values = version_after_fault(client, ['right_arm_joint3'])
        assert values['library_origin'] == 'deadline', values
        assert wait_for(lambda: rebuilt_after(node, 'parameters set: continuity_weight'),
                        30.0), node.describe()
    finally:
        assert node.stop() == 0, node.describe()
    assert 'Traceback' not in node.stderr, node.describe()


def rebuilt_after(node, line):
    """Return whether the node logged a table build after it logged ``line``."""
    after = node.stderr.split(line, 1)
    return len(after) == 2 and 'contingency table: building' in after[1]


def wait_for(predicate, timeout):
    """Return whether ``predicate()`` became true within ``timeout`` s."""
    end = time.monotonic() + timeout
    while not predicate() and time.monotonic() < end:
        time.sleep(0.05)
    return predicate()


def logged_total(line):
    """Return the library total of a logged summary line ('wai 61.96 -> 25.67 in ...')."""
    return sum(float(v) for v in re.findall(r'-> ([0-9.]+) in', line))


def test_a_miss_is_published_at_the_deadline_then_refined(tmp_path, client):
    state = tmp_path / 'state'
    # No table, and a deadline so short that the search has room to improve.
    node = NodeProcess(DOMAIN, state_dir=state,
                       args=['-p', 'contingency_table:=false', '-p', 'deadline_sec:=0.05',
                             '-p', 'refine_budget_sec:=20.0'])
    try:
        reference = client.wait_library(what='the reference library')
        client.publish_fault(['right_arm_joint1'])
        # Two versions at least: the deadline's, then a refined one.
        client.wait_for(lambda: len([v for v in client.complete_versions()
                                     if v.stamp > reference.stamp]) >= 2,
                        timeout=30.0, what='a refined library version')
        statuses = client.wait_diag(
            lambda st: statuses_values(st['reconfiguration']).get('library_origin')
            == 'refined', what='library_origin: refined')
        assert statuses_values(statuses['faults'])['failed_joints'] == 'right_arm_joint1'
    finally:
        assert node.stop() == 0, node.describe()
    lines = node.stderr.splitlines()
    searched = [line for line in lines if 'by a live search' in line]
    refined = [line for line in lines if 'refined: ' in line]
    assert searched and refined, node.describe()
    assert lines.index(searched[0]) < lines.index(refined[0])
    assert logged_total(refined[-1]) < logged_total(searched[0]), (searched[0], refined[-1])
    assert 'Traceback' not in node.stderr, node.describe()
