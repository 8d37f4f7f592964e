"""
The real ``recovery_node`` on another robot: Talos from its URDF and recovery profile.

The node starts on ``robot_profile`` (config/robots/talos.yaml, whose URDF comes from
example-robot-data) with Talos's packaged library, over DDS in a domain of its own; a
fault on one of Talos's arm joints is published on ``/actuator_fault`` and the
reconfigured library on ``/gesture_library`` must carry Talos's joint names and hold that
joint at its lock.  The contingency table and the refinement are off: one live search.
A profile that names no URDF makes the node wait for the ``/robot_description`` topic
(as ``robot_state_publisher`` publishes it) and say so on ``/diagnostics``.
"""

from pathlib import Path

from diagnostic_msgs.msg import DiagnosticStatus
from namo_fault_recovery.resources import distribution_file
from namo_fault_recovery.ros.description_wait import QOS as DESCRIPTION_QOS
from namo_fault_recovery.runtime.robot_source import load_models, robot_source
from node_harness import NodeProcess, ros_env, RosClient, session_domain, statuses_values
import pytest
from std_msgs.msg import String

pytestmark = pytest.mark.slow

DOMAIN = session_domain(1)      # modules run one after the other: the ids are reused
ROBOTS = Path(__file__).resolve().parent.parent / 'config' / 'robots'
PROFILE = ROBOTS / 'talos.yaml'
LIBRARY = ROBOTS / 'talos_gestures.yaml'
TALOS_URDF = 'talos_data/robots/talos_reduced.urdf'
FAULTED = 'arm_left_4_joint'          # Talos's left elbow
LOCK = -1.2                           # rad, inside its limits [-2.356, 0]
START = 60.0                          # s: interpreter, URDF and capsule fit, engine warm-up


@pytest.fixture(scope='module')
def talos():
    """Return Talos and its library as the node loads them (the test's own copy)."""
    return load_models(robot_source({'robot_profile': str(PROFILE)}), str(LIBRARY))


def test_a_fault_on_talos_is_reconfigured_with_talos_joint_names(tmp_path, talos):
    robot, library = talos
    arm = robot.arms['left']
    k = arm.joint_names.index(FAULTED)
    assert arm.lower[k] < LOCK < arm.upper[k]
    node = NodeProcess(DOMAIN, state_dir=tmp_path / 'state', args=[
        '-p', f'robot_profile:={PROFILE}', '-p', f'gesture_file:={LIBRARY}',
        '-p', 'contingency_table:=false', '-p', 'refine_budget_sec:=0.0'])
    client = RosClient(DOMAIN, gestures=len(library))
    try:
        reference = client.wait_library(timeout=START, what="Talos's reference library")
        assert reference.names == list(library.names)
        for msg in reference.msgs.values():
            assert list(msg.joint_names) == list(robot.joint_names)
        assert any(abs(a - LOCK) > 0.1 for a in reference.column(FAULTED))

        since = client.diag_count()
        client.publish_fault([FAULTED], [LOCK])
        adapted = client.wait_library(after=reference.stamp, timeout=30.0,
                                      what=f'the library for {FAULTED} locked at {LOCK}')
        for msg in adapted.msgs.values():
            assert list(msg.joint_names) == list(robot.joint_names)
        assert all(abs(a - LOCK) < 1e-9 for a in adapted.column(FAULTED)), \
            adapted.column(FAULTED)
        moved = [j for j in robot.arms['left'].joint_names if j != FAULTED
                 and adapted.column(j) != reference.column(j)]
        assert moved, "the left arm's other joints were not re-optimised"
        statuses = client.wait_diag(
            lambda st: statuses_values(st['faults']).get('failed_joints') == FAULTED
            and statuses_values(st['reconfiguration']).get('up_to_date') == 'true',
            since=since, what='the fault on /diagnostics')
        assert statuses_values(statuses['reconfiguration'])['library_origin'] == 'deadline'
    finally:
        client.close()
        code = node.stop()
    assert code == 0, node.describe()
    assert 'Traceback' not in node.stderr + node.stdout, node.describe()
    assert f'robot talos ({PROFILE})' in node.stderr, node.describe()


def test_a_profile_without_urdf_waits_for_the_robot_description_topic(tmp_path, talos):
    robot, library = talos
    urdf = Path(distribution_file('example-robot-data', TALOS_URDF))
    prefix = next(p for p in urdf.parents if (p / 'share' / 'example-robot-data').is_dir())
    profile = tmp_path / 'talos_no_urdf.yaml'
    profile.write_text('\n'.join(line for line in PROFILE.read_text().splitlines()
                                 if not line.startswith('urdf:')) + '\n')
    # The document's package:// meshes are found as ROS finds them: AMENT_PREFIX_PATH.
    node = NodeProcess(DOMAIN, state_dir=tmp_path / 'state', args=[
        '-p', f'robot_profile:={profile}', '-p', f'gesture_file:={LIBRARY}',
        '-p', 'contingency_table:=false', '-p', 'refine_budget_sec:=0.0',
        '-p', 'diagnostics_period_sec:=0.2'],
        env=ros_env(DOMAIN, {'AMENT_PREFIX_PATH': str(prefix)}))
    client = RosClient(DOMAIN, gestures=len(library))
    try:
        statuses = client.wait_diag(lambda st: 'robot_description' in st, timeout=START,
                                    what='the node saying it waits for /robot_description')
        waiting = statuses['robot_description']
        assert waiting.level == DiagnosticStatus.WARN
        assert waiting.message.startswith('waiting for the URDF on /robot_description')
        assert statuses_values(waiting)['robot_profile'] == str(profile)
        assert client.latest() is None and node.alive()

        # Published as robot_state_publisher does: latched, so the order does not matter.
        publisher = client.node.create_publisher(String, '/robot_description', DESCRIPTION_QOS)
        publisher.publish(String(data=urdf.read_text()))
        reference = client.wait_library(timeout=START, what='the library once the URDF came')
        for msg in reference.msgs.values():
            assert list(msg.joint_names) == list(robot.joint_names)
        client.publish_fault([FAULTED], [LOCK])
        adapted = client.wait_library(after=reference.stamp, timeout=30.0,
                                      what=f'the library for {FAULTED}')
        assert all(abs(a - LOCK) < 1e-9 for a in adapted.column(FAULTED))
    finally:
        client.close()
        code = node.stop()
    assert code == 0, node.describe()
    assert 'Traceback' not in node.stderr + node.stdout, node.describe()
    assert 'robot_description received on /robot_description' in node.stderr, node.describe()
