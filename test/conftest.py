"""Shared fixtures: the packaged robot and library, loaded once per session."""

from pathlib import Path
import signal

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
