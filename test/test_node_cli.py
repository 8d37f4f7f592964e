"""
The ROS subcommands of ``namo-recovery``, against a real ``recovery_node`` process.

fault, clear, reconfigure, library, demo and bench latency are real rclpy clients.
"""

import io
import json
import math

from namo_fault_recovery.cli.main import main
from namo_fault_recovery.optimize.base import Clock
from namo_fault_recovery.recovery.engine import RecoverySettings
from namo_fault_recovery.recovery.motion import adapt_library
from node_harness import NodeProcess, RosClient, session_domain, statuses_values
import pytest

pytestmark = pytest.mark.slow

DOMAIN = session_domain(3)
DEMO_DOMAIN = session_domain(4)


def run(*argv, domain=DOMAIN):
    """Run one subcommand of the real command line in this domain; return (code, stdout)."""
    argv = list(argv)
    if '--domain-id' not in argv:
        argv += ['--domain-id', str(domain)]
    out = io.StringIO()
    return main(argv, out), out.getvalue()


@pytest.fixture(scope='module')
def node(tmp_path_factory):
    node = NodeProcess(DOMAIN, state_dir=tmp_path_factory.mktemp('state'))
    client = RosClient(DOMAIN)          # also sets this process' discovery environment
    try:
        client.wait_library(what='the reference library')
        yield node
    finally:
        client.close()
        assert node.stop() == 0, node.stderr


def _lock_deg(library, joint=1):
    return math.degrees(library.lock_averages('right')[joint])


def test_fault_prints_the_new_scores_and_the_lock(node, product_library):
    assert run('clear')[0] == 0
    code, text = run('fault', 'right_arm_joint2')
    assert code == 0, text
    assert 'fault reported on /actuator_fault: right_arm_joint2' in text
    assert 'new library received' in text
    for name in product_library.names:
        assert f'\n{name} ' in text
    assert f'locked: right_arm_joint2 at {_lock_deg(product_library):.2f} deg' in text


def test_fault_with_angle_in_degrees(node):
    assert run('clear')[0] == 0
    code, text = run('fault', 'left_arm_joint4', '--angle', '17.5')
    assert code == 0, text
    assert 'locked: left_arm_joint4 at 17.50 deg' in text


def test_library_marks_locked_joints(node, product_library):
    assert run('clear')[0] == 0
    assert run('fault', 'right_arm_joint2')[0] == 0
    code, text = run('library')
    assert code == 0, text
    lock = f'{_lock_deg(product_library):.2f}'
    assert f'* = locked joint: right_arm_joint2 at {lock}' in text
    for g in product_library:
        assert f'\n{g.name}\n  t = {g.keyframes[0].time_from_start:.3f} s\n' in text
    assert text.count(f'  {lock}*') == sum(len(g.keyframes) for g in product_library)
    code, text = run('library', '--json')
    doc = json.loads(text)
    assert set(doc['gestures']) == set(product_library.names)
    assert list(doc['locked_joints']) == ['right_arm_joint2']
    wai = doc['gestures']['wai'][0]
    assert wai['positions_rad']['right_arm_joint2'] == doc['locked_joints']['right_arm_joint2']


def test_reconfigure_and_clear(node):
    code, text = run('reconfigure')
    assert code == 0 and text.startswith('success'), text
    code, text = run('clear')
    assert code == 0 and 'cleared' in text
    code, text = run('library')
    assert 'no locked joint (reference library)' in text


def test_rejected_fault_exits_1_with_the_reason(node, capsys):
    code, _ = run('fault', 'right_arm_joint9')
    assert code == 1
    assert "the node rejected the fault report: unknown joint 'right_arm_joint9'" in \
        capsys.readouterr().err


def test_bad_arguments_exit_2(node, capsys):
    code, _ = run('fault', 'right_arm_joint1', 'right_arm_joint2', '--angle', '10')
    assert code == 2 and 'one angle (deg) per joint' in capsys.readouterr().err


def test_no_node_exits_1(capsys):
    code, _ = run('library', '--timeout', '1', domain=DEMO_DOMAIN)
    assert code == 1
    assert 'no recovery_node found' in capsys.readouterr().err


def test_bench_latency_reports_percentiles(node):
    code, text = run('bench', 'latency', '-n', '3', '--json')
    assert code == 0, text
    report = json.loads(text)
    assert report['fault_to_library']['n'] == 3
    # The first fault waited for the node's table to be in use (a fault while it loads
    # would time the start-up).
    assert report['table_at_start']['state'] in ('building', 'complete'), report
    assert report['reconfigure_service']['n'] == 3
    for key in ('fault_to_library', 'reconfigure_service', 'fault_to_delivery'):
        stats = report[key]
        assert 0 < stats['p50_ms'] <= stats['p95_ms'] <= stats['max_ms']
    # the middleware had the last gesture before the client's executor handed it over
    assert report['fault_to_delivery']['n'] == 3
    assert report['fault_to_delivery']['p50_ms'] <= report['fault_to_library']['max_ms']


def test_bench_latency_judges_the_libraries_as_served(node):
    """--optima: each fault's library, as published, against its best-known."""
    from namo_fault_recovery.resources import config_path
    code, text = run('bench', 'latency', '-n', '2', '--joints', 'right_arm_joint2',
                     'left_arm_joint4', '--optima',
                     str(config_path('product_best_known.yaml')), '--json')
    assert code == 0, text
    quality = json.loads(text)['served_quality']
    # The average lock of each joint is a key of the packaged library's optima.
    assert quality['judged'] == 2 and quality['without_best_known'] == 0, quality
    assert 0 <= quality['within_1pct'] <= 2 and math.isfinite(quality['max_gap_pct'])
    # Scored again by the client from the trajectories it received: the node's agree
    # (its /diagnostics carry 6 significant digits).
    assert quality['rescored_by_client'] == 2 and quality['node_score_diff_pct'] < 1e-3


def test_bench_latency_streams_the_nodes_own_joints(node, robot):
    """--joint-states-hz: the stream carries the joints of the library the node serves."""
    code, text = run('bench', 'latency', '-n', '1', '--joint-states-hz', '100', '--json')
    assert code == 0, text
    assert json.loads(text)['fault_to_library']['n'] == 1
    client = RosClient(DOMAIN)
    try:
        statuses = client.wait_diag(
            lambda s: 'inputs' in s and int(statuses_values(s['inputs'])[
                'joint_states_received']) > 0, what=f'the stream on the node ({text})')
    finally:
        client.close()
    measured = statuses_values(statuses['inputs'])['measured_joints'].split()
    assert measured == sorted(robot.joint_names)


def test_demo_runs_end_to_end(tmp_path, robot, product_library):
    code, text = run('demo', '--out-dir', str(tmp_path / 'figures'), domain=DEMO_DOMAIN)
    assert code == 0, text
    assert 'reference library received on /gesture_library' in text
    assert 'fault reported on /actuator_fault: right_arm_joint2' in text
    # The unadapted score of wai is the core's, with the average lock.
    core = adapt_library(robot, product_library, {'right_arm_joint2': None},
                         RecoverySettings(trajectory_method='kriging'), clock=Clock(0.05),
                         seed=0)
    assert f"{'wai':<14}{core['wai'].score_before:>10.2f}" in text
    assert 'calling /reconfigure_gestures' in text and '\nsuccess (' in text
    # matplotlib comes with the test extra, so the figures must be there.
    assert 'stick figure saved' in text
    for name in ('wai', 'bye', 'salute', 'side_invite'):
        png = tmp_path / 'figures' / f'{name}.png'
        assert png.read_bytes().startswith(b'\x89PNG'), png
    assert text.rstrip().endswith('node stopped cleanly (exit code 0)')
