"""Shared fixtures: the packaged robot and library, loaded once per session."""

from pathlib import Path
import shutil
import signal
import subprocess
import sys

from namo_fault_recovery import load_library, load_robot
from namo_fault_recovery.resources import DEMO_MOTION_FILE
import pytest

CONFIG_DIR = Path(__file__).resolve().parent.parent / 'config'


def _interrupted(signum, frame):
    raise KeyboardInterrupt(f'signal {signum}')


def pytest_configure(config):
    """
    Take SIGTERM as Ctrl-C: the tests unwind and their node processes are stopped.

    Python's default SIGTERM ends the session at once, and every node, simulator and
    player a test had started ran on, orphaned (a cancelled CI job, a ``kill`` of the
    session: found when two leftover simulators and players took 76 % of a core).
    """
    signal.signal(signal.SIGTERM, _interrupted)


def pytest_terminal_summary(terminalreporter):
    """
    Remove the DDS shared-memory segments that the suite's killed processes left behind.

    Tests SIGKILL nodes on purpose (a crash must lose no fault), and a killed process
    cannot remove its Fast DDS segments from /dev/shm, which is memory: about 60 files
    per test file that kills, 180 MB after a day of runs on a CI machine.  Fast DDS's own
    tool (``fastdds shm clean``, in the environment with the middleware) removes only the
    segments whose owner is gone, so a running robot's are left alone.
    """
    tool = shutil.which('fastdds') or str(Path(sys.executable).with_name('fastdds'))
    if not Path(tool).is_file():
        terminalreporter.write_line('fastdds shm clean: no fastdds tool found; '
                                    '/dev/shm left as it is')
        return
    try:
        done = subprocess.run([tool, 'shm', 'clean'], capture_output=True, text=True,
                              timeout=60)
    except (OSError, subprocess.TimeoutExpired) as exc:
        terminalreporter.write_line(f'fastdds shm clean: {exc}')
        return
    said = ', '.join(line.strip() for line in done.stdout.splitlines()
                     if 'cleaned' in line)
    terminalreporter.write_line(f'fastdds shm clean: {said or done.stdout.strip()[:200]}')


@pytest.fixture(scope='session')
def robot():
    return load_robot()


@pytest.fixture(scope='session')
def library(robot):
    """Load the paper's Table 2 poses (one keyframe per gesture)."""
    return load_library(robot, CONFIG_DIR / 'paper_gestures.yaml')


@pytest.fixture(scope='session')
def product_library(robot):
    """Load the packaged product library: Namo's four Table 2 gestures as motions."""
    return load_library(robot)


@pytest.fixture(scope='session')
def demo_library(robot):
    """Load the demo library of motions: the four gestures plus the dense 100-point circle."""
    return load_library(robot, CONFIG_DIR / DEMO_MOTION_FILE)
