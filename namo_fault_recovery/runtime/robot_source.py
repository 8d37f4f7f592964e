"""
Where the node's robot comes from: Namo's DH file, or any robot's URDF and recovery profile.

Free of ROS.  :func:`robot_source` reads the node's ``robot_file``, ``robot_profile`` and
``robot_description`` parameters into a :class:`RobotSource`, refusing a combination that
says two different things; :func:`load_models` builds the robot and loads its gesture
library.  The node and its engine process both call it: the source is small, crosses the
pipe to the engine child (a URDF document included), and the child builds its own copy.

Every refusal is one line naming the parameter or file, the value and what was expected.
"""

from dataclasses import dataclass

from ..errors import ConfigError, shorten
from ..model.gestures import load_library
from ..model.robot import load_robot


@dataclass(frozen=True)
class RobotSource:
    """
    The robot of a node: a DH robot file (None: Namo's), or a profile and its URDF.

    ``description`` is a URDF document (the ``robot_description`` parameter or topic)
    that replaces the URDF the profile names; None: the profile's ``urdf`` key.
    """

    robot_file: str | None = None
    profile: str | None = None
    description: str | None = None

    def load(self):
        """Return the robot model (ConfigError, one line, if a file is wrong)."""
        if self.profile is None:
            return load_robot(self.robot_file)
        from ..model.profile_robot import robot_from_profile
        from ..model.robot_profile import load_profile
        return robot_from_profile(load_profile(self.profile, urdf=self.description))

    def needs_description(self):
        """
        Return True if only a URDF document can complete it: a profile without ``urdf``.

        Then the node waits for the ``robot_description`` topic.  A profile that cannot
        be read returns False: loading it reports why.
        """
        if self.profile is None or self.description is not None:
            return False
        from ..model.yaml_checks import load_yaml
        try:
            return 'urdf' not in load_yaml(self.profile)
        except ConfigError:
            return False

    def describe(self):
        """Return where the robot comes from, for a log line."""
        if self.profile is None:
            return self.robot_file or 'the packaged Namo model'
        urdf = 'robot_description' if self.description else "the profile's urdf"
        return f'profile {self.profile} with {urdf}'


def robot_source(values):
    """
    Return the RobotSource of the node's parameter values (ValueError: the one-line reason).

    ``robot_profile`` and ``robot_file`` exclude each other; ``robot_description`` needs
    ``robot_profile`` (which says what the URDF does not) and must be a URDF document.
    """
    robot_file = values.get('robot_file') or None
    profile = values.get('robot_profile') or None
    description = values.get('robot_description') or None
    if profile and robot_file:
        raise ValueError(f'robot_profile: {shorten(profile)} is given with robot_file '
                         f'{shorten(robot_file)}; expected one of the two (robot_file is a DH '
                         'model, robot_profile builds the robot from its URDF)')
    if description and not profile:
        raise ValueError('robot_description: a URDF without robot_profile; expected '
                         'robot_profile too (the recovery profile names the arms, their '
                         'landmark links and the joints the recovery may move)')
    if description and not description.lstrip().startswith('<'):
        raise ValueError(f'robot_description: expected a URDF document (XML text starting '
                         f"with '<'), got {shorten(repr(description), 80)}; a URDF file goes "
                         "in the profile's urdf key")
    return RobotSource(robot_file, profile, description)


def load_models(source, gesture_file=None, on_warning=None):
    """
    Return ``(robot, library)`` of a RobotSource (or a DH robot file, or None) and a library.

    Raises ConfigError (one line).  With a profile and no ``gesture_file``, the packaged
    library (Namo's) is tried; if it does not fit, the error says to give the robot's own.
    """
    if not isinstance(source, RobotSource):
        source = RobotSource(robot_file=source)
    robot = source.load()
    try:
        return robot, load_library(robot, gesture_file, on_warning=on_warning)
    except ConfigError as exc:
        if gesture_file is not None or source.profile is None:
            raise
        raise ConfigError(source.profile, None, 'gesture_file is empty and the packaged '
                          f"library (Namo's) does not fit robot {robot.name!r} ({exc}); "
                          f'expected gesture_file set to a library of {robot.name!r}') from None
