"""
The ROS client's reading of messages, without DDS: libraries, diagnostics, answers.

A LibraryResult of the engine goes out as the node's JointTrajectory messages (the
node's own converter) and the 'reconfiguration' and 'joint' statuses written with the
shared keys; :func:`rebuild_library` must give the same result back.  The command-line
options of the ROS commands (``--namespace`` before or after the command) are checked
on the real parser.
"""

import io
import math

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from namo_fault_recovery.cli.main import build_parser, main
from namo_fault_recovery.recovery.engine import recover, RecoverySettings
from namo_fault_recovery.ros import diagnostic_keys as keys
from namo_fault_recovery.ros.client import (BadNamespace, node_diagnostics,
                                            normalise_namespace, rebuild_library,
                                            TriggerAnswer)
from namo_fault_recovery.ros.messages import library_to_msgs
import pytest
from std_srvs.srv import Trigger

JOINT = 'right_arm_joint2'
STAMP = 1_700_000_000_123_456_789
ROOT = keys.status_prefix(keys.node_fqn('/'))
ROBOT1 = keys.status_prefix(keys.node_fqn('/robot1'))


@pytest.fixture(scope='module')
def result(robot, library):
    """Return a real engine result for one failed joint (the paper's one-keyframe library)."""
    return recover(robot, library, {JOINT: None}, RecoverySettings(deadline_sec=0.2), seed=0)


def _status(prefix, name, pairs):
    return DiagnosticStatus(name=prefix + name,
                            values=[KeyValue(key=k, value=str(v)) for k, v in pairs])


def _statuses(prefix, result, stamp=STAMP, up_to_date=True):
    """Return the node's statuses of ``result``, written with the shared keys."""
    pairs = [(keys.LIBRARY_VERSION, 7), (keys.LIBRARY_STAMP, keys.format_stamp(stamp)),
             (keys.UP_TO_DATE, keys.flag(up_to_date)), (keys.OPTIMIZER, 'abc'),
             (keys.DEADLINE_SEC, result.deadline),
             (keys.WALL_TIME_SEC, f'{result.wall_time:.4f}'),
             (keys.DEADLINE_MET, keys.flag(result.deadline_met)),
             (keys.SUCCESS, keys.flag(result.success)),
             (keys.FROZEN_ARMS, ' '.join(result.frozen_arms))]
    for g in result.gestures:
        pairs += [(keys.gesture_key(g.name, keys.SCORE_BEFORE), f'{g.score_before:.6g}'),
                  (keys.gesture_key(g.name, keys.SCORE_AFTER), f'{g.score_after:.6g}'),
                  (keys.gesture_key(g.name, keys.TIME_SEC), f'{g.wall_time:.4f}'),
                  (keys.gesture_key(g.name, keys.STATUS), g.status),
                  (keys.gesture_key(g.name, keys.STAGE), g.stage)]
    out = [_status(prefix, keys.RECONFIGURATION, pairs)]
    for joint, lock in result.locks.items():
        out.append(_status(prefix, keys.joint_status(joint),
                           [(keys.JOINT, joint), (keys.LOCK_ANGLE_RAD, repr(lock)),
                            (keys.LOCK_SOURCE, 'average strategy')]))
    return out


def _msgs(robot, result, stamp=STAMP):
    header = Time(sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000)
    return {m.header.frame_id: m for m in library_to_msgs(robot.joint_names, result, header)}


def test_a_library_comes_back_as_the_engine_result(robot, result):
    array = DiagnosticArray(status=_statuses(ROOT, result))
    diagnostics = node_diagnostics(array, ROOT, arrival=1.0)
    assert diagnostics.describes(STAMP)
    back = rebuild_library(STAMP, _msgs(robot, result), diagnostics, received=2.0)
    assert back.described and back.library_version == 7 and back.stamp == STAMP
    assert back.joint_names == tuple(robot.joint_names)
    assert back.names == result.names
    assert back.result.locks == result.locks and list(back.result.locks) == [JOINT]
    assert back.result.faults == {JOINT: None}      # the strategy chose the lock
    assert back.result.settings['optimizer'] == 'abc'
    for sent, got in zip(result.gestures, back.result.gestures):
        assert got.positions == sent.positions    # float64 all the way
        assert got.times == pytest.approx(sent.times, abs=1e-9)
        assert got.score_after == pytest.approx(sent.score_after, rel=1e-5)
        assert got.score_before == pytest.approx(sent.score_before, rel=1e-5)
        assert (got.status, got.stage) == (sent.status, sent.stage)


def test_diagnostics_of_another_node_or_version_are_not_used(robot, result):
    other = DiagnosticArray(status=_statuses(ROBOT1, result))
    assert node_diagnostics(other, ROOT, arrival=1.0) is None
    mine = node_diagnostics(other, ROBOT1, arrival=1.0)
    assert mine is not None and not mine.describes(STAMP + 1)
    pending = node_diagnostics(DiagnosticArray(status=_statuses(ROOT, result,
                                                                up_to_date=False)),
                               ROOT, arrival=1.0)
    assert not pending.describes(STAMP)
    back = rebuild_library(STAMP, _msgs(robot, result), None, received=2.0)
    assert not back.described and back.result.locks == {}
    assert all(math.isnan(g.score_after) for g in back.result.gestures)
    assert [g.positions for g in back.result.gestures] == \
        [g.positions for g in result.gestures]


def test_a_reported_lock_angle_is_a_fault_angle(robot, result):
    statuses = _statuses(ROOT, result)
    lock = result.locks[JOINT]
    statuses[-1] = _status(ROOT, keys.joint_status(JOINT),
                           [(keys.JOINT, JOINT), (keys.LOCK_ANGLE_RAD, repr(lock)),
                            (keys.LOCK_SOURCE, keys.LOCK_SOURCE_REPORT)])
    diagnostics = node_diagnostics(DiagnosticArray(status=statuses), ROOT, arrival=1.0)
    back = rebuild_library(STAMP, _msgs(robot, result), diagnostics, received=2.0)
    assert back.result.faults == {JOINT: lock}


def test_the_reconfigure_answer_carries_the_version():
    message = f'reconfigured 4/4 gestures ... {keys.version_tag(12, STAMP)}'
    answer = TriggerAnswer.from_response(Trigger.Response(success=True, message=message))
    assert (answer.success, answer.library_version, answer.library_stamp) == (True, 12, STAMP)
    cleared = TriggerAnswer.from_response(Trigger.Response(success=True, message='cleared'))
    assert (cleared.library_version, cleared.library_stamp) == (None, None)
    assert keys.parse_stamp(keys.format_stamp(STAMP)) == STAMP
    assert keys.parse_stamp('12.5') is None


def test_namespaces_are_normalised_or_refused():
    assert normalise_namespace('') == '/'
    assert normalise_namespace(None) == '/'
    assert normalise_namespace('robot1') == '/robot1'
    assert normalise_namespace('/robot1/') == '/robot1'
    with pytest.raises(BadNamespace, match='1robot'):
        normalise_namespace('/1robot')


def test_a_bad_namespace_is_a_usage_error(capsys):
    assert main(['--namespace', '/bad name', 'library'], io.StringIO()) == 2
    err = capsys.readouterr().err
    assert err.startswith("namo-recovery: error: invalid namespace '/bad name'")
    assert err.count('\n') == 1


@pytest.mark.parametrize('argv, namespace, domain', [
    (['library'], '/', None),
    (['--namespace', '/robot1', 'library'], '/robot1', None),
    (['library', '--namespace', '/robot1', '--domain-id', '5'], '/robot1', 5),
    (['--namespace', '/a', '--domain-id', '3', 'fault', JOINT, '--namespace', '/b'], '/b', 3),
    (['--namespace', '/robot1', 'bench', 'latency', '-n', '1'], '/robot1', None),
    (['demo', '--namespace', '/robot2'], '/robot2', None),
])
def test_namespace_and_domain_before_or_after_the_command(argv, namespace, domain):
    args = build_parser().parse_args(argv)
    assert (args.namespace, args.domain_id) == (namespace, domain)
