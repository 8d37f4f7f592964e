"""The ``bench lock|pairs|bimanual|collision`` commands: the capabilities beyond the paper."""

from .bench import models_of, out_dir_of
from .common import UsageError


def _out(args, name):
    path = out_dir_of(args, name)
    path.mkdir(parents=True, exist_ok=True)
    return path


def _check_positive(option, value):
    if value < 1:
        raise UsageError(f'{option}: expected an integer >= 1, got {value}')


def cmd_lock(args, out):
    """Average vs optimal lock for every right-arm joint."""
    from ..benchmarks import beyond
    _check_positive('--seeds', args.seeds)
    robot, library = models_of(args)
    beyond.bench_lock(out, _out(args, 'lock'), seeds=args.seeds, robot=robot, library=library)
    return 0


def cmd_pairs(args, out):
    """Every pair of right-arm joints failing at once."""
    from ..benchmarks import beyond
    robot, library = models_of(args)
    beyond.bench_pairs(out, _out(args, 'pairs'), seed=args.seed, robot=robot, library=library)
    return 0


def cmd_bimanual(args, out):
    """Wai: stage 1 vs stage 2 under each single failure."""
    from ..benchmarks import beyond
    _check_positive('--seeds', args.seeds)
    robot, library = models_of(args)
    beyond.bench_bimanual(out, _out(args, 'bimanual'), seeds=args.seeds, robot=robot,
                          library=library)
    return 0


def cmd_collision(args, out):
    """Colliding results without and with the collision term; the Fig. 7g case."""
    from ..benchmarks import beyond
    robot, library = models_of(args)
    beyond.bench_collision(out, _out(args, 'collision'), seed=args.seed, robot=robot,
                           library=library, png=not args.no_plots)
    return 0


def cmd_motion(args, out):
    """Typical points + Kriging vs per-point exploration on the circle and the wave."""
    from ..benchmarks import motion
    if args.deadline is not None:
        motion.bench_motion_deadline(out, _out(args, 'motion'), seed=args.seed,
                                     deadline=args.deadline,
                                     robot_file=getattr(args, 'robot_file', None),
                                     gesture_file=getattr(args, 'gesture_file', None))
        return 0
    motion.bench_motion(out, _out(args, 'motion'), seed=args.seed,
                        robot_file=getattr(args, 'robot_file', None),
                        gesture_file=getattr(args, 'gesture_file', None))
    return 0


def register(bench_sub):
    """Add the beyond-the-paper benchmarks to the ``bench`` subcommands."""
    for name, func, text in (
            ('lock', cmd_lock, 'average vs optimal lock angle, per right-arm joint'),
            ('pairs', cmd_pairs, 'all 21 right-arm double faults'),
            ('bimanual', cmd_bimanual, 'Wai: stage 1 vs stage 2 (healthy arm joins)'),
            ('collision', cmd_collision, 'colliding results without/with the collision term'),
            ('motion', cmd_motion, 'whole motions: typical points + Kriging vs per point')):
        p = bench_sub.add_parser(name, help=text)
        if name in ('lock', 'bimanual'):
            p.add_argument('--seeds', type=int, default=3, help='seeds per case (default 3)')
        else:
            p.add_argument('--seed', type=int, default=0, help='seed (default 0)')
        if name == 'motion':
            p.add_argument('--deadline', type=float, default=None, metavar='S',
                           help='instead: the node case (whole library, auto) within this '
                                'deadline for every single fault, the tools and the elbow '
                                'at 0, against per point without a deadline')
        if name == 'collision':
            p.add_argument('--no-plots', action='store_true', help='skip the PNG figure')
        p.add_argument('--out', default=None, help='output directory (default bench_out/NAME)')
        p.set_defaults(func=func)
