"""
The ROS 2 install path: ``colcon build`` the package into a temporary workspace.

Checks that colcon identifies it as ``ros.ament_python``, that the executable, the share
files and the ament index marker are installed, and that the installed ``recovery_node``,
run in the workspace's environment (``. install/setup.sh``), serves the contract.
"""

import os
from pathlib import Path
import shutil
import subprocess
import sys

from namo_fault_recovery import load_library, load_robot
from node_harness import NodeProcess, ros_env, RosClient, session_domain
import pytest

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = 'namo_fault_recovery'
DOMAIN = session_domain(2)


def _colcon():
    beside = Path(sys.executable).parent / 'colcon'
    found = str(beside) if beside.is_file() else shutil.which('colcon')
    if not found:
        pytest.fail('colcon is needed for this test: pip install colcon-core colcon-ros')
    return found


def _workspace_env(install):
    """Return the environment of ``. install/setup.sh`` (what a ROS user sources)."""
    out = subprocess.run(['sh', '-c', f'. "{install}/setup.sh" && env -0'],
                         capture_output=True, check=True, timeout=60).stdout
    return dict(item.split('=', 1) for item in out.decode().split('\0') if '=' in item)


@pytest.fixture(scope='module')
def workspace(tmp_path_factory):
    ws = tmp_path_factory.mktemp('colcon_ws')
    env = dict(os.environ)
    env['PATH'] = f'{Path(sys.executable).parent}{os.pathsep}{env.get("PATH", "")}'
    result = subprocess.run(
        [_colcon(), '--log-base', str(ws / 'log'), 'build', '--base-paths', str(ROOT),
         '--build-base', str(ws / 'build'), '--install-base', str(ws / 'install')],
        cwd=ws, env=env, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout + result.stderr
    return ws


def test_colcon_identifies_an_ament_python_package(workspace):
    log = (workspace / 'log' / 'latest_build' / 'logger_all.log').read_text()
    assert f"with type 'ros.ament_python' and name '{PACKAGE}'" in log


def test_colcon_installs_the_executable_share_files_and_index_marker(workspace):
    prefix = workspace / 'install' / PACKAGE
    executable = prefix / 'lib' / PACKAGE / 'recovery_node'
    assert executable.is_file() and os.access(executable, os.X_OK)
    share = prefix / 'share' / PACKAGE
    assert (share / 'package.xml').is_file()
    for name in ('namo_robot.yaml', 'gestures.yaml', 'paper_gestures.yaml',
                 'demo_motions.yaml', 'recovery_node.yaml', 'trajectories/circle.csv'):
        assert (share / 'config' / name).is_file(), name
    # The installed demo library finds its dense trajectory beside it.
    demo = load_library(load_robot(), share / 'config' / 'demo_motions.yaml')
    assert len(demo['circle'].keyframes) == 100
    docs = [p for p in sorted((ROOT / 'msg_docs').rglob('*')) if p.is_file()]
    assert docs
    for path in docs:
        installed = share / path.relative_to(ROOT)
        assert installed.read_bytes() == path.read_bytes(), path
    assert (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / PACKAGE).is_file()


def test_installed_node_serves_the_contract(workspace, tmp_path):
    prefix = workspace / 'install' / PACKAGE
    env = _workspace_env(workspace / 'install')
    assert str(prefix) in env['AMENT_PREFIX_PATH'].split(os.pathsep)
    env = ros_env(DOMAIN, extra={k: env[k] for k in ('AMENT_PREFIX_PATH', 'PYTHONPATH')
                                 if k in env})
    node = NodeProcess(DOMAIN, state_dir=tmp_path / 'state', env=env,
                       command=[str(prefix / 'lib' / PACKAGE / 'recovery_node')])
    client = RosClient(DOMAIN)
    try:
        reference = client.wait_library(what='the library from the colcon-installed node')
        # The packaged library: Namo's four gestures (the circle is in the demo library).
        assert sorted(reference.names) == ['bye', 'salute', 'side_invite', 'wai']
        client.publish_fault(['right_arm_joint2'])
        client.wait_library(after=reference.stamp, what='a reconfigured library')
        response = client.trigger('/reconfigure_gestures')
        assert response.success, response.message
        assert client.trigger('/clear_faults').success
    finally:
        client.close()
        code = node.stop()
    assert code == 0, node.stderr
    # It ran the installed copy, on the config files found through the ament index.
    assert f'{prefix}/share/{PACKAGE}/config/namo_robot.yaml' in node.stderr + node.stdout
