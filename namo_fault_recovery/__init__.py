"""
Joint-failure recovery for the Namo gesture robot.

The numerical core (kinematics, gestures, score, optimisers, recovery) is plain numpy
and needs no ROS::

    from namo_fault_recovery import load_robot, load_library, forward_kinematics
    robot = load_robot()
    library = load_library(robot)

Subpackages, one per concern:

- :mod:`.model`: the robot, its kinematics and its gestures;
- :mod:`.objective`: the similarity score and the collision model;
- :mod:`.optimize`: population optimisers (Problem / Algorithm / minimize);
- :mod:`.recovery`: fault set and settings to an adapted library (the engine);
- :mod:`.ros`: the node, messages, persistence (the only place rclpy is used);
- :mod:`.cli`: the ``namo-recovery`` command line;
- :mod:`.benchmarks`: the benchmarks that print figures.

The names below are imported lazily, so that ``import namo_fault_recovery`` (and with it
the start of ``recovery_node``) costs nothing until they are used.
"""

import importlib

_EXPORTS = {
    'ConfigError': '.errors',
    'Gesture': '.model.gestures', 'GestureLibrary': '.model.gestures',
    'Keyframe': '.model.gestures', 'load_library': '.model.gestures',
    'ArmLandmarks': '.model.kinematics', 'forward_kinematics': '.model.kinematics',
    'ArmModel': '.model.robot', 'load_robot': '.model.robot', 'RobotModel': '.model.robot',
    'COMPONENTS': '.objective.score', 'gesture_targets': '.objective.score',
    'ScoreWeights': '.objective.score', 'SimilarityScore': '.objective.score',
    'Target': '.objective.score',
    'recover': '.recovery.engine', 'RecoverySettings': '.recovery.engine',
    'GestureResult': '.recovery.result', 'LibraryResult': '.recovery.result',
}

__all__ = sorted(_EXPORTS)
__version__ = '0.1.0'


def __getattr__(name):
    """Import an exported name on first use (PEP 562)."""
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value
    return value


def __dir__():
    """List the exported names with the module's own."""
    return sorted(set(globals()) | set(_EXPORTS))
