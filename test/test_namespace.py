"""
A node under ``__ns:=/robot1`` is reached with ``--namespace /robot1``, and only so.

The real node runs with ``--ros-args -r __ns:=/robot1``; the real ``namo-recovery``
command line (in this process, through ``main``) reports a fault, reconfigures and reads
the library there.  The same commands without the namespace look in the root namespace
of the same domain, find no node, and say so with exit code 1.
"""

import contextlib
import io
import json
import math
import time

from namo_fault_recovery.cli.main import main
from namo_fault_recovery.ros.client import RecoveryClient
from namo_fault_recovery.runtime import diagnostic_keys as keys
from node_harness import NodeProcess, session_domain
import pytest

pytestmark = pytest.mark.slow

# The demo's domain of test_node_cli: no node runs there while this module runs (modules
# run one after the other, each stops its nodes), and this module's node is in /robot1.
DOMAIN = session_domain(4)
NS = '/robot1'
JOINT = 'right_arm_joint2'
SHORT = '1'          # --timeout of the commands that must not find a node


def run(*argv):
    """Run the real command line in this module's domain; return (code, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main(['--domain-id', str(DOMAIN)] + list(argv), out)
    return code, out.getvalue(), err.getvalue()


def ok(*argv):
    """Run a command that must succeed; return its stdout."""
    code, text, err = run(*argv)
    assert code == 0, f'{argv}: exit {code}\n{text}{err}'
    return text


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
    return json.loads(ok(*namespace_args, 'library', '--json'))


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
    ok('--namespace', NS, 'clear')
    reference = _library('--namespace', NS)
    assert not _locked(reference, lock)
    text = ok('--namespace', NS, 'fault', JOINT)
    assert f'fault reported on {NS}/actuator_fault: {JOINT}' in text
    assert 'new library received' in text
    text = ok('--namespace', NS, 'reconfigure')
    assert text.startswith('success'), text
    assert '[library version' in text
    # The option after the command name works as well as before it.
    after = json.loads(ok('library', '--json', '--namespace', NS))
    assert after['stamp_ns'] > reference['stamp_ns']
    assert set(after['gestures']) == set(product_library.names)
    assert _locked(after, lock)


def test_the_namespaced_nodes_diagnostics_are_read(node, product_library):
    lock = math.degrees(product_library.lock_averages('right')[1])
    ok('--namespace', NS, 'clear')
    text = ok('--namespace', NS, 'fault', JOINT)
    assert f'locked: {JOINT} at {lock:.2f} deg' in text
    text = ok('--namespace', NS, 'library')
    assert f'* = locked joint: {JOINT} at {lock:.2f}' in text


@pytest.mark.parametrize('command', [('fault', JOINT), ('reconfigure',), ('library',),
                                     ('clear',)])
def test_commands_without_the_namespace_do_not_reach_it(node, product_library, command):
    lock = product_library.lock_averages('right')[1]
    ok('--namespace', NS, 'clear')
    ok('--namespace', NS, 'fault', JOINT)
    t0 = time.monotonic()
    code, _, err = run(*command, '--timeout', SHORT)
    elapsed = time.monotonic() - t0
    assert code == 1, err
    assert 'no recovery_node found' in err and 'namespace /,' in err, err
    # A generous bound: it gave up after its short timeout, not the 15 s default.
    assert elapsed < 10.0, elapsed
    # Nothing reached the node: in particular `clear` did not clear its fault.
    assert _locked(_library('--namespace', NS), lock)
