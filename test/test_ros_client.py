"""
The ROS client's reading of messages, without DDS: libraries, diagnostics, answers.

A LibraryResult of the engine goes out as the node's JointTrajectory messages and
``/diagnostics`` statuses (the node's own converter and writer);
:func:`rebuild_library` must give the same result back, and every name and key the
writer uses must be one of :mod:`diagnostic_keys`.  The command-line
options of the ROS commands (``--namespace`` before or after the command) are checked
on the real parser.
"""

from dataclasses import replace
import io
import math
from pathlib import Path

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from namo_fault_recovery.cli.main import build_parser, main
from namo_fault_recovery.model.gestures import load_library
from namo_fault_recovery.model.profile_robot import robot_from_profile
from namo_fault_recovery.recovery.engine import recover, RecoverySettings
from namo_fault_recovery.ros.client import (BadNamespace, Inbox, node_diagnostics,
                                            normalise_namespace, rebuild_library,
                                            TriggerAnswer)
from namo_fault_recovery.ros.diagnostics import Snapshot, statuses
from namo_fault_recovery.ros.joint_state_stream import library_pose
from namo_fault_recovery.ros.messages import library_to_msgs, PreparedMessages
from namo_fault_recovery.runtime import diagnostic_keys as keys
from namo_fault_recovery.runtime.state_store import Fault
import pytest
from robot_urdfs import installed_urdf
from std_srvs.srv import Trigger

JOINT = 'right_arm_joint2'
STAMP = 1_700_000_000_123_456_789
ROOT = keys.status_prefix(keys.node_fqn('/'))
ROBOT1 = keys.status_prefix(keys.node_fqn('/robot1'))


@pytest.fixture(scope='module')
def result(robot, library):
    """Return a real engine result for one failed joint (the paper's one-keyframe library)."""
    return recover(robot, library, {JOINT: None}, RecoverySettings(deadline_sec=0.2), seed=0)


def _statuses(robot, prefix, result, stamp=STAMP, pending=False, reported=None):
    """Return what the node's writer publishes for ``result`` (``reported``: angles)."""
    faults = {j: Fault((reported or {}).get(j)) for j in result.locks}
    snap = Snapshot(faults=faults, fault_version=3, current=result, version=7,
                    stamp_ns=stamp, pending=pending, running=False, failed=None,
                    settings=RecoverySettings())
    return statuses(robot, snap, prefix)


def _msgs(robot, result, stamp=STAMP):
    header = Time(sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000)
    return {m.header.frame_id: m for m in library_to_msgs(robot.joint_names, result, header)}


def test_prepared_messages_are_the_conversion_stamped_at_each_publication(robot, result):
    """A version prepared in advance (a table entry) goes out as converted at once."""
    from rclpy.serialization import deserialize_message
    from trajectory_msgs.msg import JointTrajectory
    prepared = PreparedMessages(robot.joint_names, limit=2)
    prepared.prepare(result)
    hit = replace(result, origin='table', deadline_met=True)     # the entry, served
    for stamp in (STAMP, STAMP + 1, 2**31 * 10**9 - 1):
        header = Time(sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000)
        raws = prepared.messages(hit, header)
        assert all(isinstance(raw, bytes) for raw in raws)       # serialized in advance
        assert [deserialize_message(raw, JointTrajectory) for raw in raws] == \
            library_to_msgs(robot.joint_names, result, header)
    other = replace(result, gestures=tuple(g for g in result.gestures))   # equal, not the entry's
    assert prepared.messages(other, header) == library_to_msgs(robot.joint_names, result, header)
    for _ in range(2):                                           # the oldest is dropped
        prepared.prepare(replace(result, gestures=tuple(g for g in result.gestures)))
    assert not isinstance(prepared.messages(hit, header)[0], bytes)


def test_a_library_comes_back_as_the_engine_result(robot, result):
    array = DiagnosticArray(status=_statuses(robot, ROOT, result))
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


def _defined_keys(gestures):
    """Return every status name and key that diagnostic_keys defines."""
    constants = {v for k, v in vars(keys).items() if k.isupper() and isinstance(v, str)}
    per_gesture = {keys.gesture_key(g, f) for g in gestures for f in keys.GESTURE_FIELDS}
    numbered = {f(i) for f in (keys.note_key, keys.rejected_key) for i in range(10)}
    return constants | per_gesture | numbered


def test_every_name_and_key_the_writer_uses_is_shared(robot, result):
    right = robot.arms['right'].joint_names
    faults = {j: Fault(0.1) for j in right}          # a frozen arm: every status kind
    snap = Snapshot(faults=faults, fault_version=3, current=result, version=7,
                    stamp_ns=STAMP, pending=False, running=False, failed=None,
                    settings=RecoverySettings(),
                    rejections=[(0.0, '/actuator_fault', 'unknown joint')], rejected_total=1)
    written = statuses(robot, snap, ROBOT1)
    defined = _defined_keys(result.names)
    names = {s.name[len(ROBOT1):] for s in written}
    assert names == ({keys.FAULTS, keys.RECONFIGURATION, keys.INPUTS, keys.STATE,
                      keys.CONTINGENCY_TABLE, keys.arm_status('right')}
                     | {keys.joint_status(j) for j in right})
    unknown = sorted({kv.key for s in written for kv in s.values} - defined)
    assert not unknown, f'keys written but not in diagnostic_keys: {unknown}'


@pytest.mark.parametrize('table, message', [
    (('off', 0, 0), 'off (contingency_table is false): every fault is searched live'),
    (('loading', 0, 0), 'loading: a fault meanwhile is searched live'),
    (('building', 12, 16), '12 fault sets served at once; 16 more being built in the '
                           'background'),
    (('complete', 28, 0), '28 fault sets served at once; every planned one is built'),
])
def test_the_contingency_table_says_how_many_faults_are_served_at_once(robot, result, table,
                                                                       message):
    snap = Snapshot(faults={}, fault_version=0, current=result, version=1, stamp_ns=STAMP,
                    pending=False, running=False, failed=None, settings=RecoverySettings(),
                    table=table)
    found = {s.name[len(ROOT):]: s for s in statuses(robot, snap, ROOT)}
    got = found[keys.CONTINGENCY_TABLE]
    assert got.message == message and got.level == DiagnosticStatus.OK
    values = {kv.key: kv.value for kv in got.values}
    assert values == {keys.TABLE_STATE: table[0], keys.TABLE_ENTRIES: str(table[1]),
                      keys.TABLE_MISSING: str(table[2])}


def test_diagnostics_of_another_node_or_version_are_not_used(robot, result):
    other = DiagnosticArray(status=_statuses(robot, ROBOT1, result))
    assert node_diagnostics(other, ROOT, arrival=1.0) is None
    mine = node_diagnostics(other, ROBOT1, arrival=1.0)
    assert mine is not None and not mine.describes(STAMP + 1)
    pending = node_diagnostics(DiagnosticArray(status=_statuses(robot, ROOT, result,
                                                                pending=True)),
                               ROOT, arrival=1.0)
    assert not pending.describes(STAMP)
    back = rebuild_library(STAMP, _msgs(robot, result), None, received=2.0)
    assert not back.described and back.result.locks == {}
    assert all(math.isnan(g.score_after) for g in back.result.gestures)
    assert [g.positions for g in back.result.gestures] == \
        [g.positions for g in result.gestures]


def test_a_reported_lock_angle_is_a_fault_angle(robot, result):
    lock = result.locks[JOINT]
    statuses = _statuses(robot, ROOT, result, reported={JOINT: lock})
    diagnostics = node_diagnostics(DiagnosticArray(status=statuses), ROOT, arrival=1.0)
    back = rebuild_library(STAMP, _msgs(robot, result), diagnostics, received=2.0)
    assert back.result.faults == {JOINT: lock}


def test_the_inbox_waits_for_complete_versions_and_their_diagnostics(robot, result):
    inbox = Inbox(ROOT)
    settled = inbox.settled(quiet=0.0, declaration=0.0)
    assert inbox.wait(settled, timeout=0.0) is None      # nothing yet
    for msg in _msgs(robot, result).values():
        inbox.add_library(msg)
    assert inbox.wait(settled, timeout=0.0) == (STAMP,)
    first = inbox.library(STAMP, diagnostics_timeout=0.0)
    assert not first.described and first.names == result.names
    later = list(_msgs(robot, result, STAMP + 5).values())
    for msg in later[:-1]:
        inbox.add_library(msg)
    assert inbox.wait(inbox.newer(STAMP), timeout=0.0) is None            # incomplete
    inbox.add_library(later[-1])
    assert inbox.wait(inbox.newer(STAMP), timeout=0.0) == (STAMP + 5,)
    inbox.add_diagnostics(DiagnosticArray(status=_statuses(robot, ROBOT1, result, STAMP + 5)))
    assert not inbox.library(STAMP + 5, diagnostics_timeout=0.0).described   # not ours
    inbox.add_diagnostics(DiagnosticArray(status=_statuses(robot, ROOT, result, STAMP + 5)))
    described = inbox.library(STAMP + 5, diagnostics_timeout=0.0)
    assert described.described and described.result.locks == result.locks


def test_a_version_is_whole_when_every_gesture_its_diagnostics_list_arrived(robot, result):
    """A late gesture (a repaired DDS fragment) after any quiet time is still waited for."""
    inbox = Inbox(ROOT)
    msgs = list(_msgs(robot, result).values())
    for msg in msgs[:-1]:
        inbox.add_library(msg)
    undeclared = inbox.settled(quiet=0.0, declaration=0.0)
    assert inbox.wait(undeclared, timeout=0.0) == (STAMP,)     # what a quiet time would take
    inbox.add_diagnostics(DiagnosticArray(status=_statuses(robot, ROOT, result)))
    assert inbox.declared(STAMP) == result.names
    assert inbox.wait(inbox.settled(quiet=0.0, declaration=0.0), timeout=0.0) is None
    assert not inbox.complete(STAMP)
    inbox.add_library(msgs[-1])
    assert inbox.wait(inbox.settled(quiet=0.0, declaration=0.0), timeout=0.0) == (STAMP,)
    assert inbox.library(STAMP, diagnostics_timeout=0.0).names == result.names


def test_an_undeclared_version_waits_its_declaration_time(robot, result):
    inbox = Inbox(ROOT)
    for msg in _msgs(robot, result).values():
        inbox.add_library(msg)
    assert inbox.declared(STAMP) is None
    assert inbox.wait(inbox.settled(quiet=0.0, declaration=60.0), timeout=0.0) is None
    assert inbox.wait(inbox.settled(quiet=60.0, declaration=0.0), timeout=0.0) is None
    assert inbox.wait(inbox.settled(quiet=0.0, declaration=0.0), timeout=0.0) == (STAMP,)


def test_the_inbox_sees_a_rejected_input(robot, result):
    inbox = Inbox(ROOT)
    since = 0.0                      # every arrival (time.monotonic()) is after it
    snap = Snapshot(faults={}, fault_version=1, current=result, version=1, stamp_ns=STAMP,
                    pending=False, running=False, failed=None,
                    settings=RecoverySettings(),
                    rejections=[(0.0, '/actuator_fault', "unknown joint 'x'")],
                    rejected_total=1)
    assert inbox.wait(inbox.rejection(since, 0), timeout=0.0) is None
    inbox.add_diagnostics(DiagnosticArray(status=statuses(robot, snap, ROOT)))
    assert inbox.wait(inbox.rejection(since, 1), timeout=0.0) is None      # not a new one
    found = inbox.wait(inbox.rejection(since, 0), timeout=0.0)
    assert found.get(keys.INPUTS, keys.LAST_REJECTED_REASON) == "unknown joint 'x'"
    assert inbox.wait(inbox.rejection(since, None), timeout=0.0) is None   # no baseline


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


def test_a_library_of_arms_of_unequal_joint_counts_comes_back_split_where_the_node_says():
    installed_urdf('talos')
    data = Path(__file__).resolve().parent / 'data'
    robot = robot_from_profile(data / 'talos76.yaml')         # 7 right joints, 6 left
    library = load_library(robot, data / 'talos76_gestures.yaml')
    result = recover(robot, library, {'arm_left_2_joint': None}, RecoverySettings(),
                     seed=0)
    diagnostics = node_diagnostics(DiagnosticArray(status=_statuses(robot, ROOT, result)),
                                   ROOT, arrival=1.0)
    back = rebuild_library(STAMP, _msgs(robot, result), diagnostics, received=2.0)
    for sent, got in zip(result.gestures, back.result.gestures):
        assert got.right_joints == 7 and len(got.positions[0]) == 13
        assert [(len(k.right), len(k.left)) for k in got.keyframes] == \
            [(7, 6)] * len(sent.times)
    undescribed = rebuild_library(STAMP, _msgs(robot, result), None, received=2.0)
    assert undescribed.result.gestures[0].right_joints == 0       # not known: halves


def test_a_torso_leaned_by_the_node_comes_back_as_the_gestures_lean():
    """Talos: every trajectory ends with its torso's joints; the client splits them out."""
    installed_urdf('talos')
    robots = Path(__file__).resolve().parent.parent / 'config' / 'robots'
    robot = robot_from_profile(robots / 'talos.yaml')
    library = load_library(robot, robots / 'talos_gestures.yaml')
    result = recover(robot, library, {'arm_right_2_joint': None},
                     RecoverySettings(deadline_sec=5.0, expand_shared=True), seed=3)
    assert result['salute'].shared and not result['wai'].shared
    diagnostics = node_diagnostics(DiagnosticArray(status=_statuses(robot, ROOT, result)),
                                   ROOT, arrival=1.0)
    header = Time(sec=STAMP // 1_000_000_000, nanosec=STAMP % 1_000_000_000)
    msgs = {m.header.frame_id: m
            for m in library_to_msgs(robot.played_joints, result, header)}
    assert all(list(m.joint_names) == list(robot.played_joints) for m in msgs.values())
    back = rebuild_library(STAMP, msgs, diagnostics, received=2.0)
    assert back.joint_names == robot.joint_names
    for sent, got in zip(result.gestures, back.result.gestures):
        assert got.positions == sent.positions and got.shared == sent.shared, sent.name
    # A /joint_states stream for this robot (bench latency, bench stream): its own
    # joints at the first gesture's start, the torso too where that gesture leans it.
    names, positions = library_pose(back)
    assert names == list(robot.joint_names) and positions == list(back.result['wai'].positions[0])
    salute = back.result['salute']
    leaned = replace(back, result=replace(back.result, gestures=(salute,)))
    names, positions = library_pose(leaned)
    assert names == list(robot.joint_names) + list(salute.shared)
    assert positions == list(salute.positions[0]) + list(salute.shared.values())
