"""
Launch Namo's fault recovery: recovery_node, with the player, simulator and views on demand.

recovery_node always runs; gesture_player, namo_sim, robot_state_publisher and RViz
start when their launch argument says so.

    ros2 launch namo_fault_recovery namo.launch.py sim:=true player:=true rviz:=true

Arguments (all 'true' or 'false'):

- ``player``: ``gesture_player``, which plays the current library on the arm controllers.
- ``sim``: ``namo_sim``, the simulated Namo in MuJoCo (the arm controllers, /joint_states).
- ``robot_state_publisher``: TF of the URDF from /joint_states (default: as ``sim``).
- ``rviz``: RViz with the packaged view (robot model, /gesture_markers, TF).

The URDF is the packaged ``config/namo.urdf``, generated from the robot file by
``namo-recovery urdf``; its root ``base_link`` is the frame of /gesture_markers.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

PACKAGE = 'namo_fault_recovery'


def generate_launch_description():
    """Return the launch description (see the module docstring for the arguments)."""
    share = get_package_share_directory(PACKAGE)
    config = os.path.join(share, 'config')
    with open(os.path.join(config, 'namo.urdf'), encoding='utf-8') as f:
        robot_description = f.read()

    arguments = [
        DeclareLaunchArgument('player', default_value='false',
                              description='start gesture_player'),
        DeclareLaunchArgument('sim', default_value='false',
                              description='start namo_sim, the simulated Namo (MuJoCo)'),
        DeclareLaunchArgument('robot_state_publisher', default_value=LaunchConfiguration('sim'),
                              description='start robot_state_publisher with the URDF'),
        DeclareLaunchArgument('rviz', default_value='false',
                              description='start RViz with the packaged view'),
    ]
    nodes = [
        Node(package=PACKAGE, executable='recovery_node', name='recovery_node',
             output='screen',
             parameters=[os.path.join(config, 'recovery_node.yaml')]),
        Node(package=PACKAGE, executable='gesture_player', name='gesture_player',
             output='screen', condition=IfCondition(LaunchConfiguration('player'))),
        Node(package=PACKAGE, executable='namo_sim', name='namo_sim', output='screen',
             condition=IfCondition(LaunchConfiguration('sim'))),
        Node(package='robot_state_publisher', executable='robot_state_publisher',
             name='robot_state_publisher', output='screen',
             parameters=[{'robot_description': robot_description}],
             condition=IfCondition(LaunchConfiguration('robot_state_publisher'))),
        Node(package='rviz2', executable='rviz2', name='rviz2', output='screen',
             arguments=['-d', os.path.join(config, 'namo.rviz')],
             condition=IfCondition(LaunchConfiguration('rviz'))),
    ]
    return LaunchDescription(arguments + nodes)
