"""
The ``profile`` command and ``bench fk`` of ``namo-recovery``.

``profile`` writes a template recovery profile from a URDF; ``bench fk`` times the
URDF-compiled kinematics against the DH kinematics on Namo.

``namo-recovery profile --urdf FILE [--out FILE]`` guesses a profile from the URDF's
kinematic tree and link names (:mod:`..model.profile_template`), writes it (or prints
it), says what it guessed and what it could not, and says whether the template loads as
it is (a person still checks it: the fingertip offset, for one, no URDF knows).
"""

import os
from pathlib import Path

from .common import UsageError, writing_out
from ..errors import ConfigError


def cmd_profile(args, out):
    """Write the template to ``--out`` (or stdout) and report the guesses; return 0."""
    from ..model.profile_template import guess_profile
    from ..model.robot_profile import load_profile
    from ..model.urdf_tree import load_urdf_tree
    tree = load_urdf_tree(args.urdf)
    urdf = Path(args.urdf).resolve()
    if args.out is None:
        out.write(guess_profile(tree, str(urdf)).text)
        return 0
    target = Path(args.out)
    ref = os.path.relpath(urdf, target.resolve().parent)
    template = guess_profile(tree, ref)
    with writing_out(args.out):
        target.write_text(template.text, encoding='utf-8')
    out.write(f'wrote {args.out}\nguessed:\n')
    out.write(''.join(f'  - {line}\n' for line in template.guessed))
    out.write('could not (check these):\n')
    out.write(''.join(f'  - {line}\n' for line in template.missing) or '  (nothing)\n')
    try:
        load_profile(target)
        out.write('the template loads as it is\n')
    except ConfigError as exc:
        out.write(f'the template does not load yet: {exc}\n')
    return 0


def register(sub):
    """Add the ``profile`` subcommand to the main parser's subcommands."""
    p = sub.add_parser('profile', help='write a template recovery profile guessed from a URDF')
    p.add_argument('--urdf', required=True, metavar='FILE', help="the robot's URDF")
    p.add_argument('--out', default=None, metavar='FILE',
                   help='write the profile to FILE and report the guesses (default: print '
                        'the profile, the guesses as its comments)')
    p.set_defaults(func=cmd_profile)
    return p


def cmd_bench_fk(args, out):
    """Time the URDF chains' FK against the DH FK on Namo, side by side; return 0."""
    from ..benchmarks import fk
    from ..model.robot import load_robot
    for option, value in (('--batch', args.batch), ('--rounds', args.rounds)):
        if value < 1:
            raise UsageError(f'{option}: expected an integer >= 1, got {value}')
    out_dir = Path(args.out) if args.out else Path('bench_out') / 'fk'
    fk.run_fk(out, load_robot(args.robot_file), batch=args.batch, rounds=args.rounds,
              seed=args.seed, out_dir=out_dir)
    return 0


def register_bench(bench_sub):
    """Add ``bench fk`` to the ``bench`` command's subcommands."""
    p = bench_sub.add_parser('fk', help='URDF-compiled FK against the DH FK on Namo')
    p.add_argument('--batch', type=int, default=1000,
                   help='configurations per call (default 1000)')
    p.add_argument('--rounds', type=int, default=300,
                   help='interleaved timing rounds (default 300)')
    p.add_argument('--seed', type=int, default=0, help='seed of the configurations')
    p.add_argument('--out', default=None, metavar='DIR',
                   help='directory of fk.json (default bench_out/fk)')
    p.set_defaults(func=cmd_bench_fk)
    return p
