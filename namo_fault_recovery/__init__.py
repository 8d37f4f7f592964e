"""
Joint-failure recovery for the Namo gesture robot.

The numerical core (kinematics, gestures, score) is plain numpy and needs no ROS::

    from namo_fault_recovery import load_robot, load_library, forward_kinematics
    robot = load_robot()
    library = load_library(robot)
"""

from .errors import ConfigError
from .gestures import Gesture, GestureLibrary, Keyframe, load_library
from .kinematics import ArmLandmarks, forward_kinematics
from .robot_model import ArmModel, load_robot, RobotModel
from .score import COMPONENTS, gesture_targets, ScoreWeights, SimilarityScore, Target

__all__ = [
    'ArmLandmarks', 'ArmModel', 'COMPONENTS', 'ConfigError', 'Gesture', 'GestureLibrary',
    'Keyframe', 'RobotModel', 'ScoreWeights', 'SimilarityScore', 'Target',
    'forward_kinematics', 'gesture_targets', 'load_library', 'load_robot',
]
__version__ = '0.1.0'
