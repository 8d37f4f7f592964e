"""Shared fixtures: the packaged robot and library, loaded once per session."""

from pathlib import Path

from namo_fault_recovery import load_library, load_robot
from namo_fault_recovery.resources import DEMO_MOTION_FILE
import pytest

CONFIG_DIR = Path(__file__).resolve().parent.parent / 'config'


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
