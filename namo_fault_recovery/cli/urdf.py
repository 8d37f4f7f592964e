"""
The ``urdf`` command of ``namo-recovery``: write Namo's URDF, generated from the robot file.

The URDF is what robot_state_publisher, RViz and the MuJoCo simulator load; it comes
from the same robot file as the optimiser's kinematics (``--robot-file``), so the two
cannot drift apart.  The packaged ``config/namo.urdf`` is this command's output for the
packaged robot file.
"""

from pathlib import Path

from .common import writing_out


def cmd_urdf(args, out):
    """Write the URDF to ``--out`` (or stdout); return 0."""
    from ..model.robot import load_robot
    from ..model.urdf import urdf_string
    text = urdf_string(load_robot(args.robot_file))
    if args.out is None:
        out.write(text)
        return 0
    with writing_out(args.out):
        Path(args.out).write_text(text, encoding='utf-8')
    out.write(f'wrote {args.out}\n')
    return 0


def register(sub):
    """Add the ``urdf`` subcommand to the main parser's subcommands."""
    p = sub.add_parser('urdf', help="write Namo's URDF (generated from the robot file)")
    p.add_argument('--out', default=None, metavar='FILE',
                   help='write it to FILE (default: print it)')
    p.set_defaults(func=cmd_urdf)
    return p
