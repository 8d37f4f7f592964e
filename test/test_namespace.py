"""
A node under ``__ns:=/robot1`` is reached with ``--namespace /robot1``, and only so.

The real node runs with ``--ros-args -r __ns:=/robot1``; the real ``namo-recovery``
command line (in this process, through ``main``) reports a fault, reconfigures and reads
the library there.  The same commands without the namespace look in the root namespace
of the same domain, find no node, and say so with exit code 1.
"""

import io
import json
import math
import time

from namo_fault_recovery.cli.main import main
from namo_fault_recovery.ros import diagnostic_keys as keys
from namo_fault_recovery.ros.client import RecoveryClient
from node_harness import NodeProcess, session_domain
import pytest

pytestmark = pytest.mark.slow

DOMAIN = session_domain(5)
NS = '/robot1'
JOINT = 'right_arm_joint2'
SHORT = '1'          # --timeout of the commands that must not find a node


def run(*argv):
    """Run the real command line in this module's domain; return (code, stdout)."""
    out = io.StringIO()
    return main(['--domain-id', str(DOMAIN)] + list(argv), out), out.getvalue()


@pytest.fixture(scope='module')
def node(tmp_path_factory):
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
        node = NodeProcess(DOMAIN, state_dir=tmp_path_factory.mktemp('state'),
                           args=['-r', f'__ns:={NS}'])
        try:
            with RecoveryClient(NS, DOMAIN) as client:
                client.current_library(timeout=30.0, diagnostics_timeout=0.0)
            yield node
        finally:
            assert node.stop() == 0, node.describe()


def _library(*namespace_args):
    code, text = run(*namespace_args, 'library', '--json')
    assert code == 0, text
    return json.loads(text)


def _column(doc, joint):
    return [p['positions_rad'][joint] for points in doc['gestures'].values() for p in points]


def _locked(doc, lock):
    """Return True if JOINT sits at ``lock`` in every keyframe of every gesture."""
    return all(math.isclose(a, lock, abs_tol=1e-9) for a in _column(doc, JOINT))


def test_the_prefix_names_the_node_and_its_namespace():
    assert keys.status_prefix(keys.node_fqn('/')) == 'recovery_node: '
    assert keys.status_prefix(keys.node_fqn('')) == 'recovery_node: '
    assert keys.status_prefix(keys.node_fqn('/robot1')) == 'robot1/recovery_node: '
    assert keys.status_prefix(keys.node_fqn('robot1/')) == 'robot1/recovery_node: '


def test_commands_with_the_namespace_reach_the_node(node, product_library):
    lock = product_library.lock_averages('right')[1]
    assert run('--namespace', NS, 'clear')[0] == 0
    reference = _library('--namespace', NS)
    assert not _locked(reference, lock)
    code, text = run('--namespace', NS, 'fault', JOINT)
    assert code == 0, text
    assert f'fault reported on {NS}/actuator_fault: {JOINT}' in text
    assert 'new library received' in text
    code, text = run('--namespace', NS, 'reconfigure')
    assert code == 0 and text.startswith('success'), text
    assert '[library version' in text
    # The option after the command name works as well as before it.
    code, text = run('library', '--json', '--namespace', NS)
    assert code == 0, text
    after = json.loads(text)
    assert after['stamp_ns'] > reference['stamp_ns']
    assert set(after['gestures']) == set(product_library.names)
    assert _locked(after, lock)


def test_the_namespaced_nodes_diagnostics_are_read(node, product_library):
    lock = math.degrees(product_library.lock_averages('right')[1])
    assert run('--namespace', NS, 'clear')[0] == 0
    code, text = run('--namespace', NS, 'fault', JOINT)
    assert code == 0, text
    assert f'locked: {JOINT} at {lock:.2f} deg' in text
    code, text = run('--namespace', NS, 'library')
    assert f'* = locked joint: {JOINT} at {lock:.2f}' in text


@pytest.mark.parametrize('command', [('fault', JOINT), ('reconfigure',), ('library',),
                                     ('clear',)])
def test_commands_without_the_namespace_do_not_reach_it(node, product_library, capsys,
                                                        command):
    lock = product_library.lock_averages('right')[1]
    assert run('--namespace', NS, 'fault', JOINT)[0] == 0
    capsys.readouterr()
    t0 = time.monotonic()
    code, _ = run(*command, '--timeout', SHORT)
    elapsed = time.monotonic() - t0
    err = capsys.readouterr().err
    assert code == 1, err
    assert 'no recovery_node found' in err and 'namespace /,' in err, err
    # A generous bound: it gave up after its short timeout, not the 15 s default.
    assert elapsed < 10.0, elapsed
    # Nothing reached the node: in particular `clear` did not clear its fault.
    assert _locked(_library('--namespace', NS), lock)
