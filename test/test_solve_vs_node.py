"""
One engine path: ``namo-recovery solve --json`` gives the library the node publishes.

The node and the command line both call ``recover()``.  With the same fault, the same
seed and no deadline that binds (the node at ``deadline_sec:=60``, ``solve
--no-deadline``), the published library must equal the solved one, angle for angle.
"""

import io
import json

from namo_fault_recovery.cli.main import main
from node_harness import NodeProcess, RosClient, session_domain
import pytest

DOMAIN = session_domain(4)
FAULT = 'right_arm_joint2'


@pytest.mark.slow
def test_solve_json_equals_the_library_the_node_publishes(tmp_path):
    out = io.StringIO()
    assert main(['solve', '--fault', FAULT, '--seed', '0', '--no-deadline', '--json'],
                out=out) == 0
    solved = json.loads(out.getvalue())
    # The live path only: a table hit serves the best of the table's seeds, which since
    # 2026-12-04 all reach this fault's optimum up to the last bits (64.880176414926xx,
    # seed 3 lowest by 1e-13), so it is seed 0's library only up to rounding.
    node = NodeProcess(DOMAIN, state_dir=tmp_path,
                       args=['-p', 'seed:=0', '-p', 'deadline_sec:=60.0',
                             '-p', 'contingency_table:=false'])
    client = RosClient(DOMAIN, name='solve_vs_node')
    try:
        reference = client.wait_library(what='the reference library')
        client.publish_fault([FAULT])
        published = client.wait_library(
            lambda v: len(set(v.column(FAULT))) == 1 and v.column(FAULT)[0] != 0.0,
            after=reference.stamp, timeout=120.0, what='the library for the fault')
    finally:
        client.close()
        assert node.stop() == 0, node.describe()
    assert solved['seed'] == 0 and solved['deadline'] is None
    assert sorted(published.names) == sorted(g['name'] for g in solved['gestures'])
    for gesture in solved['gestures']:
        assert published.positions(gesture['name']) == gesture['positions'], gesture['name']
