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

import contextlib
import math
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticStatus
from namo_fault_recovery.resources import distribution_file
from namo_fault_recovery.ros.description_wait import QOS as DESCRIPTION_QOS
from namo_fault_recovery.runtime.robot_source import load_models, robot_source
from node_harness import NodeProcess, ros_env, RosClient, session_domain, statuses_values
import pytest
from robot_urdfs import TALOS_URDF
from std_msgs.msg import String

pytestmark = pytest.mark.slow

DOMAIN = session_domain(1)      # modules run one after the other: the ids are reused
ROBOTS = Path(__file__).resolve().parent.parent / 'config' / 'robots'
PROFILE = ROBOTS / 'talos.yaml'
LIBRARY = ROBOTS / 'talos_gestures.yaml'
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
            assert list(msg.joint_names) == list(robot.played_joints)   # the torso's last
        assert any(abs(a - LOCK) > 0.1 for a in reference.column(FAULTED))

        since = client.diag_count()
        client.publish_fault([FAULTED], [LOCK])
        adapted = client.wait_library(after=reference.stamp, timeout=30.0,
                                      what=f'the library for {FAULTED} locked at {LOCK}')
        for msg in adapted.msgs.values():
            assert list(msg.joint_names) == list(robot.played_joints)   # the torso's last
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
    assert f"robot talos (profile {PROFILE} with the profile's urdf)" in node.stderr, \
        node.describe()


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
            assert list(msg.joint_names) == list(robot.played_joints)   # the torso's last
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
    assert f'robot talos (profile {profile} with robot_description)' in node.stderr, \
        node.describe()


def test_the_gesture_player_runs_on_talos_and_commands_its_arm_joints(tmp_path, talos):
    """gesture_player on the same profile: Talos's library in, its arms and torso out."""
    import threading
    import time

    from namo_fault_recovery.runtime.private_node import player_command
    from sensor_msgs.msg import JointState
    from std_srvs.srv import Trigger
    from trajectory_msgs.msg import JointTrajectory
    robot, library = talos
    robot_args = ['-p', f'robot_profile:={PROFILE}', '-p', f'gesture_file:={LIBRARY}']
    node = NodeProcess(DOMAIN, state_dir=tmp_path / 'state', args=robot_args + [
        '-p', 'contingency_table:=false', '-p', 'refine_budget_sec:=0.0'])
    player = NodeProcess(DOMAIN, command=player_command(), env=ros_env(DOMAIN),
                         args=robot_args + ['-p', 'carry_on_wait_sec:=0.0'])
    client = RosClient(DOMAIN, gestures=len(library))
    commands = []
    client.node.create_subscription(JointTrajectory, 'right_arm_controller/joint_trajectory',
                                    commands.append, 10)
    client.node.create_subscription(JointTrajectory, 'left_arm_controller/joint_trajectory',
                                    commands.append, 10)
    client.node.create_subscription(JointTrajectory, 'torso_controller/joint_trajectory',
                                    commands.append, 10)
    stop = threading.Event()

    def stream():                       # Talos at rest, as its joint_state_broadcaster
        while not stop.wait(0.02):
            client.state_pub.publish(JointState(name=list(robot.played_joints),
                                                position=[0.0] * len(robot.played_joints)))
    streamer = threading.Thread(target=stream, daemon=True)
    streamer.start()
    try:
        client.wait_library(timeout=START, what="Talos's reference library")
        play = client.node.create_client(Trigger, '/gesture_player/play/salute')
        assert play.wait_for_service(timeout_sec=START), player.describe()
        play.call_async(Trigger.Request())
        end = time.monotonic() + 20.0
        while len(commands) < 3 and time.monotonic() < end:
            time.sleep(0.05)
        assert len(commands) == 3, player.describe()
        sent = {tuple(msg.joint_names): msg for msg in commands}
        assert set(sent) == {tuple(robot.arms['right'].joint_names),
                             tuple(robot.arms['left'].joint_names), robot.shared.names}
        assert all(msg.points for msg in commands)
        # The salute does not lean: the torso is held upright through it.
        assert all(p.positions[0] == p.positions[1] == 0.0
                   for p in sent[robot.shared.names].points)
    finally:
        stop.set()
        streamer.join()
        client.close()
        codes = [proc.stop() for proc in (player, node)]
    assert codes == [0, 0], player.describe() + node.describe()
    assert 'Traceback' not in player.stderr + player.stdout, player.describe()


@contextlib.contextmanager
def _talos_loop(tmp_path, library, stuck, node_args=()):
    """
    Run namo_sim (``stuck``: its stuck_joints entry), recovery_node and gesture_player.

    Yields ``(client, faults, states, describe)``: a RosClient, the /actuator_fault and
    /joint_states messages it received, and what the player and the node said so far;
    stops the three and checks they ended cleanly.
    """
    from namo_fault_recovery.ros.sim_node import sim_command
    from namo_fault_recovery.runtime.private_node import player_command
    from sensor_msgs.msg import JointState
    robot_args = ['-p', f'robot_profile:={PROFILE}', '-p', f'gesture_file:={LIBRARY}']
    node = NodeProcess(DOMAIN, state_dir=tmp_path / 'state', args=robot_args + [
        '-p', 'contingency_table:=false', '-p', 'refine_budget_sec:=0.0', *node_args])
    sim = NodeProcess(DOMAIN, command=sim_command(), env=ros_env(DOMAIN),
                      args=robot_args + ['-p', f"stuck_joints:=['{stuck}']"])
    player = NodeProcess(DOMAIN, command=player_command(), env=ros_env(DOMAIN),
                         args=robot_args)
    client = RosClient(DOMAIN, gestures=len(library))
    faults, states = [], []
    client.node.create_subscription(JointState, '/actuator_fault', faults.append, 10)
    client.node.create_subscription(JointState, '/joint_states', states.append, 10)
    procs = (player, sim, node)
    try:
        yield client, faults, states, lambda: player.describe() + node.describe()
    finally:
        client.close()
        codes = [proc.stop() for proc in procs]
    assert codes == [0, 0, 0], ''.join(p.describe() for p in procs)
    for proc in procs:
        assert 'Traceback' not in proc.stderr + proc.stdout, proc.describe()


def _salute_carried_on(loop, joint):
    """Play salute with ``joint`` stuck; return (its play client, the fault's library)."""
    from std_srvs.srv import Trigger
    client, faults, _, describe = loop
    reference = client.wait_library(timeout=START, what="Talos's reference library")
    play = client.node.create_client(Trigger, '/gesture_player/play/salute')
    assert play.wait_for_service(timeout_sec=START), describe()
    first = _call(client, play, 60.0)
    assert first.success, first.message + describe()
    assert 'carried on' in first.message and joint in first.message, first.message
    assert any(joint in msg.name for msg in faults), faults
    adapted = client.wait_library(after=reference.stamp, timeout=30.0,
                                  what=f'the library for {joint}')
    return play, adapted


@pytest.mark.parametrize('lean', [False, True], ids=['upright', 'leaned'])
def test_talos_end_to_end_on_the_simulator_stuck_detected_reconfigured_replayed(
        tmp_path, talos, lean):
    """
    namo_sim, recovery_node and gesture_player, all on Talos's profile, over DDS.

    Talos's right shoulder (arm_right_2_joint) is stuck at rest in the simulator; playing
    salute, which swings it 94 deg, detects it, reports it, and carries on with the
    library reconfigured for it; salute is then played again on that library.  Rest is
    that joint's upper limit: the simulator reads it a little past (its encoder noise),
    which the node first rejected as out of limits, so nothing was reconfigured.

    ``leaned``: the node's ``expand_shared`` on, salute (159 mm off with the arms alone)
    leans the torso; the player commands it on torso_controller and the simulated torso
    ends the replay where the library says.
    """
    robot, library = talos
    joint = 'arm_right_2_joint'
    with _talos_loop(tmp_path, library, f'{joint}:0.0',
                     ['-p', f'expand_shared:={str(lean).lower()}']) as loop:
        client, _, states, _ = loop
        play, adapted = _salute_carried_on(loop, joint)
        assert all(abs(a) < math.radians(1.0) for a in adapted.column(joint))
        salute = adapted.msgs['salute']
        torso = [salute.points[-1].positions[list(salute.joint_names).index(n)]
                 for n in robot.shared.names]
        assert any(torso) == lean, torso
        second = _call(client, play, 60.0)
        assert second.success and 'carried on' not in second.message, second.message
        last = dict(zip(states[-1].name, states[-1].position))
        for name, angle in zip(robot.shared.names, torso):
            assert abs(last[name] - angle) < math.radians(0.5), (name, last[name], angle)


def _call(client, service, timeout):
    """Call a Trigger service from the client's node; return its response."""
    import time

    from std_srvs.srv import Trigger
    future = service.call_async(Trigger.Request())
    end = time.monotonic() + timeout
    while not future.done() and time.monotonic() < end:
        time.sleep(0.05)
    assert future.done(), f'no answer within {timeout:g} s'
    return future.result()


def test_talos_torso_stuck_on_the_simulator_the_arms_make_up_for_it(tmp_path, talos):
    """
    Talos's torso_2_joint stuck 10 deg forward in namo_sim: salute detects and reports it.

    The node takes a fault of a joint both arms hang from: every gesture holds the torso
    where it stuck and the arms make up for it; the play carries on with that library.
    """
    _, library = talos
    joint = 'torso_2_joint'
    with _talos_loop(tmp_path, library, f'{joint}:10.0') as loop:
        client = loop[0]
        play, adapted = _salute_carried_on(loop, joint)
        held = adapted.column(joint)
        assert all(abs(a - math.radians(10.0)) < math.radians(0.5) for a in held), held
        assert len(set(held)) == 1              # one angle, where it stuck, everywhere
        second = _call(client, play, 60.0)
        assert second.success and 'carried on' not in second.message, second.message
