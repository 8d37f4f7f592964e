"""
The simulated Namo (``namo_sim``) as a real process over DDS.

One simulator serves the module (its own ROS domain).  A trajectory controller client
sends trajectories as a gesture player would, and reads ``/joint_states`` and
``~/contacts`` back: the arm follows, bad messages are rejected with a reason, a stuck
joint stays put, and the reference Wai makes no self-contact.  Talos, from its recovery
profile and URDF (example-robot-data), runs in the same simulator: its arms follow a key
pose of its library while a stuck joint holds.
"""

import math
from pathlib import Path
import threading
import time

from builtin_interfaces.msg import Duration, Time
from diagnostic_msgs.msg import DiagnosticArray
from namo_fault_recovery import load_library, load_robot
from namo_fault_recovery.ros.description_wait import QOS as DESCRIPTION_QOS
from namo_fault_recovery.ros.sim_node import sim_command
from namo_fault_recovery.ros.spun_node import SpunNode, wait_until
from namo_fault_recovery.runtime.robot_source import load_models, robot_source
from namo_fault_recovery.sim.trajectory import ActiveTrajectory, Command, Point
from node_harness import NodeProcess, session_domain
import numpy as np
import pytest
from robot_urdfs import installed_urdf
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
import yaml

pytestmark = pytest.mark.slow

# The first two of this session's module domains: the recovery_node modules that use them
# have stopped their processes before this module starts (modules run one after another).
DOMAIN = session_domain(0)
OTHER_DOMAIN = session_domain(1)
ROBOT = load_robot()
RIGHT = list(ROBOT.arms['right'].joint_names)
LEFT = list(ROBOT.arms['left'].joint_names)
ALL = RIGHT + LEFT
TIMEOUT = 20.0
ROBOTS = Path(__file__).resolve().parent.parent / 'config' / 'robots'


def seconds(msg):
    return msg.sec + msg.nanosec * 1e-9


def time_msg(t):
    sec = int(math.floor(t))
    return Time(sec=sec, nanosec=int((t - sec) * 1e9))


def trajectory(names, points, stamp=0.0):
    """Return a JointTrajectory from [(t, positions)] (rad)."""
    msg = JointTrajectory(joint_names=list(names))
    msg.header.stamp = time_msg(stamp) if stamp else Time()
    for t, q in points:
        sec = int(math.floor(t))
        msg.points.append(JointTrajectoryPoint(
            positions=[float(v) for v in q],
            time_from_start=Duration(sec=sec, nanosec=int(round((t - sec) * 1e9)))))
    return msg


class SimClient:
    """Publishers to the two controllers; recorders of /joint_states and ~/contacts."""

    def __init__(self, domain=DOMAIN):
        self._spun = SpunNode('namo_sim_test_client', domain)
        self.node = self._spun.node
        self.lock = threading.RLock()
        self.states = []          # (stamp s, positions by name)
        self.reports = []
        self.pubs = {c: self.node.create_publisher(JointTrajectory,
                                                   f'/{c}/joint_trajectory', 10)
                     for c in ('right_arm_controller', 'left_arm_controller')}
        self.stick_pub = self.node.create_publisher(JointState, '/namo_sim/stick', 10)
        self.release_pub = self.node.create_publisher(JointState, '/namo_sim/release', 10)
        self.node.create_subscription(JointState, '/joint_states', self._on_state, 100)
        self.node.create_subscription(DiagnosticArray, '/namo_sim/contacts',
                                      self._on_report, 10)
        self.reset_client = self.node.create_client(Trigger, '/namo_sim/reset_contacts')
        self._spun.start()

    def close(self):
        self._spun.close()

    def _on_state(self, msg):
        with self.lock:
            self.states.append((seconds(msg.header.stamp),
                                dict(zip(msg.name, msg.position)),
                                dict(zip(msg.name, msg.velocity))))

    def _on_report(self, msg):
        values = {kv.key: kv.value for kv in msg.status[0].values}
        with self.lock:
            self.reports.append((time.monotonic(), values))

    def now(self):
        return self.node.get_clock().now().nanoseconds * 1e-9

    def wait(self, predicate, what, timeout=TIMEOUT):
        value = wait_until(predicate, timeout, lock=self.lock)
        if not value:
            raise AssertionError(f'timed out waiting for {what}')
        return value

    def latest(self):
        with self.lock:
            return self.states[-1][1] if self.states else None

    def states_between(self, t0, t1):
        with self.lock:
            return [s for s in self.states if t0 <= s[0] <= t1]

    def send(self, controller, msg):
        pub = self.pubs[controller]
        self.wait(lambda: pub.get_subscription_count() > 0, f'{controller} subscriber')
        pub.publish(msg)

    def report_after(self, moment):
        """Return the first ~/contacts values received after ``moment`` (monotonic)."""
        def find():
            for t, values in self.reports:
                if t > moment:
                    return values
            return None
        return self.wait(find, 'a ~/contacts report')

    def reset_contacts(self):
        assert self.reset_client.wait_for_service(timeout_sec=TIMEOUT)
        done = threading.Event()
        future = self.reset_client.call_async(Trigger.Request())
        future.add_done_callback(lambda _: done.set())
        assert done.wait(TIMEOUT)
        assert future.result().success


@pytest.fixture(scope='module')
def sim():
    process = NodeProcess(DOMAIN, command=sim_command(),
                          args=['-p', "stuck_joints:=['left_arm_joint4:30.0']"])
    client = SimClient()
    try:
        client.wait(lambda: client.states, 'the first /joint_states')
        yield process, client
    finally:
        client.close()
        code = process.stop()
        assert code == 0, process.describe()
        assert 'Traceback' not in process.stderr + process.stdout


@pytest.fixture
def client(sim):
    process, client = sim
    assert process.alive(), process.describe()
    yield client
    assert process.alive(), process.describe()


def move_to(client, q_right, q_left=None, duration=1.0):
    """Send both arms to a pose (zero stamp) and wait until they are there."""
    client.send('right_arm_controller', trajectory(RIGHT, [(duration, q_right)]))
    if q_left is not None:
        client.send('left_arm_controller', trajectory(LEFT, [(duration, q_left)]))
    target = dict(zip(RIGHT, q_right))
    if q_left is not None:
        target.update(zip(LEFT, q_left))

    def there():
        state = client.states[-1][1] if client.states else {}
        return all(abs(state.get(n, 1e9) - v) < math.radians(0.5) for n, v in target.items())
    client.wait(there, 'the arms to reach the pose', timeout=duration + 10.0)


def test_joint_states_name_all_14_joints_with_velocities(client):
    client.wait(lambda: len(client.states) > 20, 'joint states')
    with client.lock:
        stamps = [s[0] for s in client.states[-21:]]
        last = client.states[-1]
    assert list(last[1]) == ALL and list(last[2]) == ALL
    rate = 20 / (stamps[-1] - stamps[0])
    assert 60.0 < rate < 140.0, f'/joint_states at {rate:.1f} Hz'


def test_stuck_joints_parameter_holds_until_released(client):
    stuck = math.radians(30.0)
    client.wait(lambda: abs(client.latest()['left_arm_joint4'] - stuck) < math.radians(0.05),
                'left_arm_joint4 at its stuck angle')
    report = client.report_after(time.monotonic())
    assert report['stuck'] == 'left_arm_joint4:30.000', report
    client.send('left_arm_controller', trajectory(LEFT, [(0.5, [0.0] * 7)]))
    time.sleep(1.0)
    assert abs(client.latest()['left_arm_joint4'] - stuck) < math.radians(0.1)
    client.wait(lambda: client.release_pub.get_subscription_count() > 0, 'the ~/release topic')
    client.release_pub.publish(JointState(name=['left_arm_joint4']))
    client.wait(lambda: client.reports[-1][1]['stuck'] == '', 'the release')
    move_to(client, [0.0] * 7, [0.0] * 7)


def test_a_bad_stuck_joint_parameter_is_a_one_line_error():
    process = NodeProcess(OTHER_DOMAIN, command=sim_command(),
                          args=['-p', "stuck_joints:=['right_arm_joint9:3.0']"])
    try:
        assert process.wait() == 1
    finally:
        process.stop()
    assert "namo_sim: error: unknown joint 'right_arm_joint9'" in process.stderr
    assert 'Traceback' not in process.stderr


def test_right_arm_follows_a_trajectory(client):
    move_to(client, [0.0] * 7)
    a = np.radians([30, -20, -20, 60, 10, -20, 30])   # clear of the torso
    b = np.radians([50, -10, 20, 90, -30, 10, 0])
    start = client.now() + 0.5            # a stamp in the future: the start is known
    points = [(1.0, a), (2.0, b)]
    client.send('right_arm_controller', trajectory(RIGHT, points, stamp=start))
    client.wait(lambda: client.states and client.states[-1][0] > start + 2.6,
                'the trajectory to end')
    expected = ActiveTrajectory(
        Command(tuple(RIGHT), start, tuple(Point(t, tuple(q)) for t, q in points)),
        RIGHT, start, (np.zeros(7), np.zeros(7)))
    errors = []
    for stamp, q, _ in client.states_between(start, start + 2.6):
        measured = np.array([q[n] for n in RIGHT])
        errors.append(np.abs(measured - expected.sample(stamp)[0]).max())
    assert len(errors) > 150
    worst = math.degrees(max(errors))
    final = np.array([client.latest()[n] for n in RIGHT])
    print(f'tracking error over the trajectory: max {worst:.3f} deg, '
          f'mean {math.degrees(np.mean(errors)):.3f} deg; final '
          f'{math.degrees(np.abs(final - b).max()):.4f} deg')
    assert worst < 1.5
    assert np.abs(final - b).max() < math.radians(0.2)
    # The left arm was not commanded and stays at rest.
    assert max(abs(client.latest()[n]) for n in LEFT) < math.radians(0.2)


@pytest.mark.parametrize('case, names, points, stamp, reason', [
    ('unknown joint', RIGHT[:6] + ['right_arm_joint8'], [(1.0, [0.5] * 7)], None,
     "incoming joint right_arm_joint8 doesn't match"),
    ("the other arm's joint", RIGHT[:6] + ['left_arm_joint7'], [(1.0, [0.5] * 7)], None,
     "incoming joint left_arm_joint7 doesn't match"),
    ('past stamp', RIGHT, [(1.0, [0.5] * 7)], -100.0, 'ends in the past'),
    ('times not increasing', RIGHT, [(1.0, [0.5] * 7), (1.0, [0.6] * 7)], None,
     'not strictly increasing'),
])
def test_bad_trajectory_is_rejected_with_its_reason(sim, case, names, points, stamp, reason):
    process, client = sim
    move_to(client, [0.0] * 7)
    before = len(process.stderr + process.stdout)
    stamp_value = client.now() + stamp if stamp is not None else 0.0
    client.send('right_arm_controller', trajectory(names, points, stamp=stamp_value))
    client.wait(lambda: 'rejected trajectory' in (process.stderr + process.stdout)[before:],
                f'the rejection of the {case}')
    assert reason in (process.stderr + process.stdout)[before:]
    time.sleep(1.2)      # the trajectory's length: had it run, the arm would have moved
    assert max(abs(client.latest()[n]) for n in RIGHT) < math.radians(0.2), case


def test_stuck_joint_stays_while_commanded_elsewhere(sim):
    _, client = sim
    move_to(client, [0.0] * 7)
    stuck = math.radians(-20.0)
    msg = JointState(name=['right_arm_joint2'], position=[stuck])
    client.wait(lambda: client.stick_pub.get_subscription_count() > 0, 'the ~/stick topic')
    client.stick_pub.publish(msg)
    client.wait(lambda: abs(client.latest()['right_arm_joint2'] - stuck) < math.radians(0.05),
                'the joint to reach its stuck angle')
    t0 = client.now()
    target = np.radians([40, 30, 20, 70, 10, 10, 10])
    client.send('right_arm_controller', trajectory(RIGHT, [(1.5, target)]))
    client.wait(lambda: client.states[-1][0] > t0 + 2.5, 'the trajectory to end')
    held = [q['right_arm_joint2'] for _, q, _ in client.states_between(t0, t0 + 2.5)]
    assert len(held) > 150
    worst = math.degrees(max(abs(a - stuck) for a in held))
    print(f'stuck joint: max deviation {worst:.4f} deg from -20 deg')
    assert worst < 1.0
    others = [n for n in RIGHT if n != 'right_arm_joint2']
    final = client.latest()
    assert all(abs(final[n] - t) < math.radians(0.5)
               for n, t in zip(RIGHT, target) if n in others)
    client.release_pub.publish(JointState(name=['right_arm_joint2']))
    move_to(client, [0.0] * 7)


def test_reference_wai_makes_no_self_contact_and_the_torso_does(sim):
    _, client = sim
    wai = load_library(ROBOT)['wai']
    move_to(client, [0.0] * 7, [0.0] * 7)
    client.reset_contacts()
    # The reference Wai as a player sends it: each arm to its own controller.
    times = wai.times
    right = [(float(t), kf.right) for t, kf in zip(times, wai.keyframes)]
    left = [(float(t), kf.left) for t, kf in zip(times, wai.keyframes)]
    client.send('right_arm_controller', trajectory(RIGHT, right))
    client.send('left_arm_controller', trajectory(LEFT, left))
    t_end = time.monotonic() + float(times[-1]) + 0.5
    client.wait(lambda: time.monotonic() > t_end, 'the Wai to end', timeout=times[-1] + 5)
    report = client.report_after(time.monotonic())
    assert report['contact_events'] == '0', report
    assert report['contact_steps'] == '0', report
    final = client.latest()
    q_wai = np.concatenate((wai.keyframes[-1].right, wai.keyframes[-1].left))
    assert max(abs(final[n] - v) for n, v in zip(ALL, q_wai)) < math.radians(0.5)
    # The counter can count: the right arm swung in against the torso.
    move_to(client, [0.0] * 7, [0.0] * 7)
    client.reset_contacts()
    client.send('right_arm_controller',
                trajectory(RIGHT, [(1.0, np.radians([0, 40, 0, 0, 0, 0, 0]))]))
    time.sleep(1.5)
    report = client.report_after(time.monotonic())
    assert int(report['contact_events']) >= 1, report
    assert float(report['max_depth_mm']) > 1.0, report
    assert 'torso' in report['pairs_since_reset'], report
    move_to(client, [0.0] * 7, [0.0] * 7)


def test_talos_from_its_profile_follows_a_key_pose_while_a_stuck_joint_holds():
    installed_urdf('talos')
    profile, library = ROBOTS / 'talos.yaml', ROBOTS / 'talos_gestures.yaml'
    robot, gestures = load_models(robot_source({'robot_profile': str(profile)}), str(library))
    right = list(robot.arms['right'].joint_names)
    stuck = math.radians(-40.0)
    process = NodeProcess(OTHER_DOMAIN, command=sim_command(), args=[
        '-p', f'robot_profile:={profile}', '-p', f'gesture_file:={library}',
        '-p', "stuck_joints:=['arm_left_4_joint:-40.0']"])
    client = SimClient(OTHER_DOMAIN)
    try:
        client.wait(lambda: client.states, "Talos's first /joint_states", timeout=40.0)
        assert list(client.latest()) == list(robot.played_joints)      # the arms, the torso
        client.reset_contacts()
        pose = gestures['bye'].keyframes[0].positions()[:len(right)]
        move_to_pose = trajectory(right, [(1.5, pose)])
        client.send('right_arm_controller', move_to_pose)

        def there():
            state = client.latest()
            return all(abs(state[n] - v) < math.radians(0.1) for n, v in zip(right, pose))
        client.wait(there, "Talos's right arm at the bye key pose", timeout=15.0)
        assert abs(client.latest()['arm_left_4_joint'] - stuck) < math.radians(0.1)
        report = client.report_after(time.monotonic())
        assert report['contact_events'] == '0' and report['stuck'] == 'arm_left_4_joint:-40.000'
    finally:
        client.close()
        code = process.stop()
    assert code == 0, process.describe()
    assert 'Traceback' not in process.stderr + process.stdout


def test_a_robot_of_unequal_arms_starts_where_told_and_its_six_joint_arm_follows():
    """
    Talos with a 7-joint right arm and a 6-joint left one: 13 joints, started at 0 rad.

    Its torso (2 shared joints) is simulated too: 15 joints on /joint_states.
    """
    installed_urdf('talos')
    data = Path(__file__).resolve().parent / 'data'
    profile, library = data / 'talos76.yaml', data / 'talos76_gestures.yaml'
    robot, gestures = load_models(robot_source({'robot_profile': str(profile)}), str(library))
    left = list(robot.arms['left'].joint_names)
    # initial_positions left at its default, one angle (0 rad) for every joint: it
    # was 14 zeros, which this robot's 13 joints refused at start-up.
    process = NodeProcess(OTHER_DOMAIN, command=sim_command(), args=[
        '-p', f'robot_profile:={profile}', '-p', f'gesture_file:={library}'])
    client = SimClient(OTHER_DOMAIN)
    try:
        client.wait(lambda: client.states, 'the first /joint_states', timeout=40.0)
        first = client.latest()
        assert list(first) == list(robot.played_joints) and len(first) == 13 + 2
        assert np.abs(np.array(list(first.values()))).max() < math.radians(1.0), first
        pose = gestures['wai'].keyframes[0].left
        client.send('left_arm_controller', trajectory(left, [(1.5, list(pose))]))

        def there():
            state = client.latest()
            return all(abs(state[n] - v) < math.radians(0.1) for n, v in zip(left, pose))
        client.wait(there, "the 6-joint left arm at Wai's key pose", timeout=15.0)
    finally:
        client.close()
        code = process.stop()
    assert code == 0, process.describe()
    assert 'Traceback' not in process.stderr + process.stdout


def test_a_profile_naming_no_urdf_waits_for_the_robot_description_topic(tmp_path):
    urdf = installed_urdf('talos')
    doc = yaml.safe_load((ROBOTS / 'talos.yaml').read_text())
    del doc['urdf']
    profile = tmp_path / 'talos_without_urdf.yaml'
    profile.write_text(yaml.safe_dump(doc))
    process = NodeProcess(OTHER_DOMAIN, command=sim_command(), args=[
        '-p', f'robot_profile:={profile}',
        '-p', f"gesture_file:={ROBOTS / 'talos_gestures.yaml'}"])
    client = SimClient(OTHER_DOMAIN)
    try:
        time.sleep(2.0)
        assert not client.states and process.alive(), process.describe()   # it waits
        pub = client.node.create_publisher(String, '/robot_description', DESCRIPTION_QOS)
        pub.publish(String(data=Path(urdf).read_text()))
        client.wait(lambda: client.states, '/joint_states after the URDF', timeout=40.0)
        assert list(client.latest())[0] == 'arm_right_1_joint'
    finally:
        client.close()
        code = process.stop()
    assert code == 0, process.describe()
    assert 'waiting for the URDF on /robot_description' in process.stderr + process.stdout
