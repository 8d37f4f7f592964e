"""
``namo-recovery`` subcommands around the ``gesture_player`` node.

rclpy is imported only when one of them runs, so the rest of the command line works
without ROS.
"""

from pathlib import Path
import shutil
import sys


def player_command():
    """Return the command that starts the ``gesture_player`` executable."""
    beside = Path(sys.executable).parent / 'gesture_player'
    if beside.is_file():
        return [str(beside)]
    found = shutil.which('gesture_player')
    if found:
        return [found]
    return [sys.executable, '-m', 'namo_fault_recovery.ros.player_node']
