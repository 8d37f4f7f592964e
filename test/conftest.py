"""Shared fixtures: the packaged robot and library, loaded once per session."""

from pathlib import Path

from namo_fault_recovery import load_library, load_robot
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
    """Load the packaged product library: Table 2 gestures as motions, plus the circle."""
    return load_library(robot)
