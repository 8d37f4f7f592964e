"""
Joint-failure recovery for the Namo gesture robot.

The numerical core (kinematics, gestures, score, optimisers, recovery) is plain numpy
and needs no ROS::

    from namo_fault_recovery import load_robot, load_library, forward_kinematics
    robot = load_robot()
    library = load_library(robot)

Subpackages, one per concern, from the bottom layer up (a module imports its own layer
and those below it, never one above; ``test/test_layout.py`` checks it):

- :mod:`.model`: the robot, its kinematics, its gestures and the score weights;
- :mod:`.objective`: the similarity score and the collision model;
- :mod:`.optimize`: population optimisers (Problem / Algorithm / minimize);
- :mod:`.recovery`: fault set and settings to an adapted library (the engine, its one
  result type and its one settings declaration);
- :mod:`.sim`: the simulated Namo's physics (MuJoCo);
- :mod:`.playback`: the gesture player's core (timing, stuck-joint detection);
- :mod:`.runtime`: the node's runtime, free of ROS (run book, intake, dispatcher,
  engine process, contingency keeper, persistence, private node processes);
- :mod:`.ros`: the modules that import rclpy or a message package (the nodes, the
  messages, the clients), and only those;
- :mod:`.benchmarks`: every benchmark that prints figures;
- :mod:`.cli`: the ``namo-recovery`` command line, which parses and calls.

Root modules: :mod:`.errors` (the one-line errors), :mod:`.resources` and :mod:`.files`.

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
