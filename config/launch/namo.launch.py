"""
Launch Namo's fault recovery: recovery_node, with the player, simulator and views on demand.

recovery_node always runs; gesture_player, namo_sim, robot_state_publisher and RViz
start when their launch argument says so.

    ros2 launch namo_fault_recovery namo.launch.py sim:=true player:=true rviz:=true

Arguments (all 'true' or 'false'):

- ``player``: ``gesture_player``, which plays the current library on the arm controllers.
- ``sim``: ``namo_sim``, the simulated robot in MuJoCo (the arm controllers, /joint_states).
- ``robot_state_publisher``: TF of the URDF from /joint_states (default: as ``sim``).
- ``rviz``: RViz with the packaged view (robot model, /gesture_markers, TF).

``thread_priority`` (an integer, default 50; 0: the normal scheduler) is the
``SCHED_FIFO`` priority of ``recovery_node``'s and ``gesture_player``'s own threads, as
ros2_control's controller manager runs its loop: on a busy robot a table hit then
reaches the player within about 5 ms (README, "The served problem").  A user without
an ``rtprio`` allowance (``/etc/security/limits.conf``) gets one warning per node, which
then runs under the normal scheduler.

Another robot (strings; empty: Namo):

- ``robot_profile``: its recovery profile YAML, for ``recovery_node``,
  ``gesture_player`` and ``namo_sim`` (the robot from its URDF instead of Namo's model);
- ``gesture_file``: its gesture library (``namo-recovery retarget`` makes one);
- ``urdf``: the URDF that ``robot_state_publisher`` (and so RViz) shows and publishes
  on ``/robot_description``; a profile without a ``urdf`` key makes ``recovery_node``
  wait for that topic.

    ros2 launch namo_fault_recovery namo.launch.py player:=true \
        robot_profile:=/path/to/talos.yaml gesture_file:=/path/to/talos_gestures.yaml \
        urdf:=/path/to/talos_reduced.urdf robot_state_publisher:=true

The default URDF is the packaged ``config/namo.urdf``, generated from the robot file by
``namo-recovery urdf``; its root ``base_link`` is the frame of /gesture_markers.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import Command, LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

PACKAGE = 'namo_fault_recovery'


def generate_launch_description():
    """Return the launch description (see the module docstring for the arguments)."""
    share = get_package_share_directory(PACKAGE)
    config = os.path.join(share, 'config')
    robot_description = ParameterValue(Command(['cat ', LaunchConfiguration('urdf')]),
                                       value_type=str)
    # Strings, even when empty (launch_ros would otherwise read '' as YAML: no value).
    robot = {'robot_profile': ParameterValue(LaunchConfiguration('robot_profile'),
                                             value_type=str),
             'gesture_file': ParameterValue(LaunchConfiguration('gesture_file'), value_type=str)}

    priority = {'thread_priority': ParameterValue(LaunchConfiguration('thread_priority'),
                                                  value_type=int)}

    arguments = [
        DeclareLaunchArgument('player', default_value='false',
                              description='start gesture_player'),
        DeclareLaunchArgument('sim', default_value='false',
                              description='start namo_sim, the simulated Namo (MuJoCo)'),
        DeclareLaunchArgument('robot_state_publisher', default_value=LaunchConfiguration('sim'),
                              description='start robot_state_publisher with the URDF'),
        DeclareLaunchArgument('rviz', default_value='false',
                              description='start RViz with the packaged view'),
        DeclareLaunchArgument('robot_profile', default_value='',
                              description="another robot's recovery profile (empty: Namo)"),
        DeclareLaunchArgument('gesture_file', default_value='',
                              description="that robot's gesture library (empty: Namo's)"),
        DeclareLaunchArgument('thread_priority', default_value='50',
                              description="SCHED_FIFO priority of recovery_node's and "
                                          "gesture_player's threads (0: normal scheduler)"),
        DeclareLaunchArgument('urdf', default_value=os.path.join(config, 'namo.urdf'),
                              description='URDF for robot_state_publisher and RViz'),
    ]
    nodes = [
        Node(package=PACKAGE, executable='recovery_node', name='recovery_node',
             output='screen',
             parameters=[os.path.join(config, 'recovery_node.yaml'), robot, priority]),
        Node(package=PACKAGE, executable='gesture_player', name='gesture_player',
             output='screen', parameters=[robot, priority],
             condition=IfCondition(LaunchConfiguration('player'))),
        Node(package=PACKAGE, executable='namo_sim', name='namo_sim', output='screen',
             parameters=[robot], condition=IfCondition(LaunchConfiguration('sim'))),
        Node(package='robot_state_publisher', executable='robot_state_publisher',
             name='robot_state_publisher', output='screen',
             parameters=[{'robot_description': robot_description}],
             condition=IfCondition(LaunchConfiguration('robot_state_publisher'))),
        Node(package='rviz2', executable='rviz2', name='rviz2', output='screen',
             arguments=['-d', os.path.join(config, 'namo.rviz')],
             condition=IfCondition(LaunchConfiguration('rviz'))),
    ]
    return LaunchDescription(arguments + nodes)
