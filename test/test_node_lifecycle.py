"""
Start-up, shutdown and restart of the real ``recovery_node`` process.

Covers: SIGKILL then restart restores and republishes the faults and the library; a
corrupted state file is set aside, never fatal; SIGTERM and SIGINT exit 0 without a
traceback, also mid-run; an invalid configuration refuses to start with one clear line;
``--params-file`` is honoured.
"""

import json
import math
from pathlib import Path
import signal
import subprocess
import time

from namo_fault_recovery import load_library, load_robot
from namo_fault_recovery.runtime.state_store import decode_state, StateStore
from node_harness import (forked_starts, NodeProcess, RosClient, session_domain,
                          statuses_values)
import pytest

pytestmark = pytest.mark.slow

DOMAIN = session_domain(1)
ROOT = Path(__file__).resolve().parent.parent
NAN = float('nan')


@pytest.fixture
def client():
    client = RosClient(DOMAIN)
    yield client
    client.close()


def no_traceback(node):
    text = node.stdout + node.stderr
    assert 'Traceback' not in text and 'Exception' not in text, text


def test_sigkill_then_restart_restores_and_republishes(tmp_path, client):
    state = tmp_path / 'state'
    node = NodeProcess(DOMAIN, state_dir=state)
    try:
        reference = client.wait_library(what='the reference library')
        client.publish_fault(['right_arm_joint3', 'left_arm_joint1'], [NAN, 0.2])
        faulted = client.wait_library(
            lambda v: all(a == 0.2 for a in v.column('left_arm_joint1')),
            after=reference.stamp, what='the library for the faults')
        # The library is written right after it is published (off the publish path; the
        # faults were written before they were acknowledged): kill once it is on disk.
        end = time.monotonic() + 10.0
        while time.monotonic() < end:
            stored = StateStore(state).load()[0]       # the faults first, in the journal
            saved = stored.library if stored is not None else None
            if saved is not None and set(saved.locks) == {'right_arm_joint3',
                                                          'left_arm_joint1'}:
                break
            time.sleep(0.01)
        else:
            pytest.fail('the library for the faults was not written to the state file')
        node.send(signal.SIGKILL)
        assert node.wait() == -signal.SIGKILL
    finally:
        node.stop()
    assert (state / 'state.json').is_file()

    node = NodeProcess(DOMAIN, state_dir=state)
    try:
        # The restarted node republishes the very same library (restored, not recomputed:
        # a new optimisation with a fresh random seed would give other angles).
        restored = client.wait_library(
            lambda v: all(v.positions(g) == faulted.positions(g) for g in faulted.names),
            after=faulted.stamp, what='the restored library')
        assert restored.stamp > faulted.stamp
        late = RosClient(DOMAIN, name='late_after_restart')
        try:
            again = late.wait_library(what='the restored library via transient local')
            for name in faulted.names:
                assert again.positions(name) == faulted.positions(name)
        finally:
            late.close()
        statuses = client.wait_diag(lambda s: 'joint left_arm_joint1' in s
                                    and 'joint right_arm_joint3' in s,
                                    what='diagnostics of the restored faults')
        assert statuses_values(statuses['joint left_arm_joint1'])['lock_angle_rad'] == '0.2'
        robot = load_robot()
        average = load_library(robot).lock_averages('right')[2]
        assert all(a == average for a in restored.column('right_arm_joint3'))
        # The restored state is live: clearing it works and is persisted too.
        assert client.trigger('/clear_faults').success
        assert StateStore(state).load()[0].faults == {}     # as a restart reads it
    finally:
        assert node.stop() == 0
    no_traceback(node)


def test_restart_with_another_tool_recomputes_instead_of_restoring(tmp_path, client):
    state = tmp_path / 'state'
    node = NodeProcess(DOMAIN, state_dir=state)
    try:
        reference = client.wait_library(what='the reference library')
        client.publish_fault(['right_arm_joint4'], [0.0])
        faulted = client.wait_library(after=reference.stamp, what='the library for the fault')
    finally:
        assert node.stop() == 0
    saved = decode_state((state / 'state.json').read_text()).library
    assert saved.tool_mm == 0.0

    node = NodeProcess(DOMAIN, state_dir=state, args=['-p', 'tool_length_mm:=50.0'])
    try:
        statuses = client.wait_diag(
            lambda s: ('reconfiguration' in s
                       and statuses_values(s['reconfiguration']).get('tool_length_mm') == '50'
                       and statuses_values(s['reconfiguration'])['up_to_date'] == 'true'),
            what='diagnostics of the library recomputed for the tool')
        assert 'joint right_arm_joint4' in statuses
        latest = client.wait_library(
            lambda v: any(v.positions(n) != faulted.positions(n) for n in faulted.names),
            after=faulted.stamp, what='a library for the tool, not the restored one')
        assert all(a == 0.0 for a in latest.column('right_arm_joint4'))
    finally:
        assert node.stop() == 0
    assert 'the tool (tool_length_mm, tool_arm) changed since it was saved' in node.stderr
    no_traceback(node)


@pytest.mark.parametrize('content, reason', [
    ('{"format": "namo_fault_recovery/state", "version": 1, "faults": {', 'not valid JSON'),
    ('[1, 2, 3]', 'not a namo_fault_recovery/state document'),
    (json.dumps({'format': 'namo_fault_recovery/state', 'version': 1,
                 'faults': {'tail_joint': {'angle': 0.1}}, 'library': None}),
     "unknown joint 'tail_joint'"),
    (json.dumps({'format': 'namo_fault_recovery/state', 'version': 1,
                 'faults': {'right_arm_joint1': {'angle': 9.0}}, 'library': None}),
     'outside its limits'),
    ('[' * 100_000, 'nested too deeply'),
], ids=['truncated', 'not a state', 'unknown joint', 'out of limits', 'deeply nested'])
def test_corrupted_state_file_is_set_aside(tmp_path, client, content, reason):
    state = tmp_path / 'state'
    state.mkdir()
    (state / 'state.json').write_text(content)
    node = NodeProcess(DOMAIN, state_dir=state)
    try:
        client.wait_library(what='the reference library')
        statuses = client.wait_diag(lambda s: s['state'].level == s['state'].WARN,
                                    what='diagnostics reporting the corrupted state file')
        assert 'corrupted' in statuses['state'].message
        assert reason in statuses['state'].message
        assert 'set aside' in statuses['state'].message
        aside = list(state.glob('state.json.corrupt-*'))
        assert len(aside) == 1 and aside[0].read_text() == content
        assert statuses_values(statuses['faults'])['failed_joints'] == ''
        # The node works normally and writes a good state file again.
        before = client.latest().stamp
        client.publish_fault(['right_arm_joint2'])
        client.wait_library(after=before, what='a library after the fault')
        assert list(StateStore(state).load()[0].faults) == ['right_arm_joint2']
        assert node.alive()
    finally:
        assert node.stop() == 0
    no_traceback(node)


@pytest.mark.parametrize('sig', [signal.SIGTERM, signal.SIGINT], ids=['SIGTERM', 'SIGINT'])
def test_signal_gives_a_clean_exit(tmp_path, client, sig):
    node = NodeProcess(DOMAIN, state_dir=tmp_path)
    try:
        client.wait_library(what='the reference library')
        node.send(sig)
        assert node.wait() == 0, node.describe()
    finally:
        node.stop()
    no_traceback(node)


@pytest.mark.parametrize('delay', [0.3, 0.7, 1.2, 2.0])
@pytest.mark.parametrize('sig', [signal.SIGTERM, signal.SIGINT], ids=['SIGTERM', 'SIGINT'])
def test_a_signal_at_any_moment_of_start_up_exits_cleanly(tmp_path, sig, delay):
    # Imports, rclpy.init, the engine process start and the restore all take place in
    # the first second or two: a signal in any of them must end the node with exit 0.
    # (Only the interpreter's own start, some 30-90 ms before any code of ours runs,
    # cannot be covered: a signal then has its default effect.  On a loaded machine that
    # start takes longer than the shortest delay, so the delay counts from the start, but
    # the signal waits until the node catches it.)
    started = time.monotonic()
    node = NodeProcess(DOMAIN, state_dir=tmp_path)
    try:
        assert wait_until_caught(node.proc.pid, sig), node.describe()
        time.sleep(max(0.0, started + delay - time.monotonic()))
        node.send(sig)
        assert node.wait() == 0, node.describe()
    finally:
        node.stop()
    no_traceback(node)


def wait_until_caught(pid, sig, timeout=20.0):
    """Return True once process ``pid`` catches ``sig`` (its handler installed)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            status = Path(f'/proc/{pid}/status').read_text()
        except OSError:
            return False
        caught = next(int(line.split()[1], 16) for line in status.splitlines()
                      if line.startswith('SigCgt:'))
        if caught & (1 << (sig - 1)):
            return True
        time.sleep(0.001)
    return False


def test_sigterm_during_an_optimisation_exits_cleanly(tmp_path, client):
    # The paper's ABC preset with a long deadline keeps the worker busy for a while.
    node = NodeProcess(DOMAIN, state_dir=tmp_path, args=[
        '-p', 'optimizer_preset:=paper', '-p', 'deadline_sec:=20.0'])
    try:
        client.wait_library(what='the reference library')
        since = client.diag_count()
        client.publish_fault(['right_arm_joint2', 'right_arm_joint4', 'left_arm_joint3'])
        client.wait_diag(lambda s: statuses_values(s['reconfiguration'])['running'] == 'true',
                         since=since, what='diagnostics saying a run is in progress')
        node.send(signal.SIGTERM)
        assert node.wait() == 0, node.describe()
    finally:
        node.stop()
    no_traceback(node)


def _write(path, text):
    path.write_text(text)
    return str(path)


BAD_CONFIGS = [
    ('gesture file not YAML', lambda d: ['-p', 'gesture_file:=' + _write(
        d / 'g.yaml', 'units: deg\ngestures: [\n')], 'not valid YAML'),
    ('gesture file empty', lambda d: ['-p', 'gesture_file:=' + _write(d / 'g.yaml', '')],
     'g.yaml'),
    ('gesture library empty', lambda d: ['-p', 'gesture_file:=' + _write(
        d / 'g.yaml', 'units: deg\ngestures: []\n')], 'the library is empty'),
    ('gesture with unknown joint', lambda d: ['-p', 'gesture_file:=' + _write(
        d / 'g.yaml', 'units: deg\ngestures:\n- name: wave\n  arms: [right]\n'
        '  two_handed: false\n  keyframes:\n  - time_from_start: 1.0\n'
        '    right: {tail: 0}\n    left: [0, 0, 0, 0, 0, 0, 0]\n')], "unknown joint 'tail'"),
    ('robot file missing', lambda d: ['-p', 'robot_file:=/nonexistent/robot.yaml'],
     '/nonexistent/robot.yaml'),
    ('robot profile and robot file', lambda d: [
        '-p', f'robot_profile:={ROOT}/config/robots/talos.yaml',
        '-p', f'robot_file:={ROOT}/config/namo_robot.yaml'],
     'invalid parameter robot_profile: '),
    ('robot profile naming a missing URDF', lambda d: ['-p', 'robot_profile:=' + _write(
        d / 'p.yaml', 'name: x\nurdf: gone.urdf\narms: {}\n')],
     "p.yaml: key 'urdf': no URDF file "),
    ('library of another robot', lambda d: [
        '-p', f'gesture_file:={ROOT}/config/robots/talos_gestures.yaml'],
     "key 'robot': a library for robot 'talos', whose joints are not those of robot 'namo'"),
    ('negative deadline', lambda d: ['-p', 'deadline_sec:=-1.0'], 'deadline_sec'),
    ('integer deadline', lambda d: ['-p', 'deadline_sec:=2'], 'write 2.0, not 2'),
    ('unknown lock strategy', lambda d: ['-p', 'lock_strategy:=bogus'],
     "lock_strategy: unknown value 'bogus'"),
    ('unknown optimizer', lambda d: ['-p', 'optimizer:=pso'], "unknown value 'pso'"),
    ('unknown preset', lambda d: ['-p', 'optimizer_preset:=fast'], "unknown value 'fast'"),
    ('seed out of range', lambda d: ['-p', 'seed:=-7'], 'seed'),
    ('all arm weights zero', lambda d: ['-p', 'weights.elbow:=0.0', '-p', 'weights.wrist:=0.0',
                                        '-p', 'weights.tip:=0.0', '-p', 'weights.palm:=0.0'],
     'at least one of elbow, wrist, tip, palm'),
    ('params file not YAML', lambda d: ['--params-file', _write(d / 'p.yaml', 'a: [\n')],
     'not valid YAML'),
    ('params file without ros__parameters', lambda d: ['--params-file', _write(
        d / 'p.yaml', 'recovery_node:\n  deadline_sec: 1.0\n')], 'ros__parameters'),
    ('params file missing', lambda d: ['--params-file', str(d / 'none.yaml')],
     'cannot read parameter file'),
    ('bad value in a params file', lambda d: ['--params-file', _write(
        d / 'bad_value.yaml', '/**:\n  ros__parameters:\n    lock_strategy: bogus\n')],
     "lock_strategy: unknown value 'bogus'; expected one of average, measured, optimal "
     '(in '),
]


# Run as node processes of their own, end to end (console script, exit code, stderr): one
# refusal of each stage (parameter file read before ROS, rcl's file parsing with the
# file named, rclpy's type check, the setting check, the gesture file).  The others run
# the same main() in forks of one process that imported the node once (node_refusals.py).
END_TO_END = ('params file not YAML', 'params file missing', 'bad value in a params file',
              'integer deadline', 'gesture file not YAML')
REFUSAL_TIMEOUT = 120.0     # all refusals start at once: generous on 2 shared cores


@pytest.fixture(scope='module')
def refused(tmp_path_factory):
    """
    Start every bad configuration, all at once; return ``{case: (code, outcome)}``.

    Each refusal is a start-up of its own (own process, files and state directory) that
    ends before it reaches the network, so they need not wait for one another; the
    interpreter start-ups then share both cores.  ``code`` is None if it did not exit.
    """
    nodes, forked = {}, {}
    for case, make_args, _ in BAD_CONFIGS:
        folder = tmp_path_factory.mktemp('bad_config')
        if case in END_TO_END:
            nodes[case] = NodeProcess(DOMAIN, state_dir=folder / 'state', args=make_args(folder))
        else:
            forked[case] = make_args(folder) + ['-p', f'state_dir:={folder / "state"}']
    out = {case: (start.code, start) for case, start in zip(
        forked, forked_starts(DOMAIN, list(forked.values()), REFUSAL_TIMEOUT))}
    for case, node in nodes.items():
        try:
            code = node.wait(timeout=REFUSAL_TIMEOUT)
        except subprocess.TimeoutExpired:
            code = None
        node.stop()
        out[case] = (code, node)
    return out


@pytest.mark.parametrize('case, expected', [(c[0], c[2]) for c in BAD_CONFIGS],
                         ids=[c[0] for c in BAD_CONFIGS])
def test_invalid_config_refuses_to_start_with_one_clear_line(refused, case, expected):
    code, node = refused[case]
    assert code == 1, node.describe()
    lines = [line for line in node.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, node.stderr
    assert lines[0].startswith('recovery_node: error: ')
    assert expected in lines[0]
    no_traceback(node)


def test_params_file_sets_the_parameters(tmp_path, client):
    override = tmp_path / 'override.yaml'
    override.write_text('recovery_node:\n  ros__parameters:\n    deadline_sec: 0.5\n'
                        '    optimizer: ga\n    weights:\n      palm: 2.0\n')
    node = NodeProcess(DOMAIN, state_dir=tmp_path / 'state', args=[
        '--params-file', str(ROOT / 'config' / 'recovery_node.yaml'),
        '--params-file', str(override)])
    try:
        client.wait_library(what='the reference library')
        assert client.get_parameters('deadline_sec', 'optimizer', 'weights.palm',
                                     'weights.elbow', 'lock_strategy', 'seed') == [
            0.5, 'ga', 2.0, 1.0, 'average', -1]
        statuses = client.wait_diag(lambda s: 'reconfiguration' in s)
        recon = statuses_values(statuses['reconfiguration'])
        assert recon['optimizer'] == 'ga' and math.isclose(float(recon['deadline_sec']), 0.5)
    finally:
        assert node.stop() == 0
    no_traceback(node)


def test_diagnostics_keep_coming_with_use_sim_time_and_no_clock(tmp_path, client):
    # Periodic work runs on a steady clock: simulated time that never advances (no
    # /clock publisher) must not stop /diagnostics.
    node = NodeProcess(DOMAIN, state_dir=tmp_path, args=['-p', 'use_sim_time:=true'])
    try:
        client.wait_library(what='the reference library')
        since = client.diag_count()
        time.sleep(3.5)                  # the diagnostics period is 1 s
        assert client.diag_count() - since >= 3, 'periodic /diagnostics stopped'
    finally:
        assert node.stop() == 0, node.describe()
    no_traceback(node)
