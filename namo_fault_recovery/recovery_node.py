"""Entry point of the ``recovery_node`` ROS 2 node (arrives with the node issue)."""

import sys


def main(argv=None):
    """Print usage and exit non-zero: the node is not implemented yet."""
    sys.stderr.write('recovery_node: the ROS 2 node is not implemented in this version; '
                     'use `namo-recovery show` or `namo-recovery score`.\n')
    return 1


if __name__ == '__main__':
    sys.exit(main())
