"""
A stand-in for ``namo_sim`` in the demo test: ``player_harness.FakeArms`` as a process.

Takes ``--ros-args -p stuck_joints:=['joint:deg', ...]`` like the simulator and runs in
``$ROS_DOMAIN_ID`` until SIGINT or SIGTERM.
"""

import math
import os
import signal
import sys
import threading

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from player_harness import FakeArms  # noqa: E402 - after the path set-up above


def _stuck(argv):
    for i, arg in enumerate(argv):
        if arg.startswith('stuck_joints:=') and i > 0 and argv[i - 1] == '-p':
            items = arg.split(':=', 1)[1].strip('[]').split(',')
            out = {}
            for item in filter(None, (s.strip().strip('\'"') for s in items)):
                joint, value = item.split(':')
                out[joint] = math.radians(float(value))
            return out
    return {}


def main():
    done = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: done.set())
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    arms = FakeArms(int(os.environ.get('ROS_DOMAIN_ID', '0')), name='namo_sim')
    with arms.lock:
        arms.stuck = _stuck(sys.argv)
    done.wait()
    arms.close()
    return 0


if __name__ == '__main__':
    sys.exit(main())
