"""``namo-recovery bench notice``: noticing a structure change (benchmarks.notice)."""


def cmd_bench_notice(args, out):
    """Run the noticing benchmark and write its JSON summary."""
    from .bench import out_dir_of
    from ..benchmarks import common, notice
    if args.seeds < 1:
        out.write(f'--seeds: {args.seeds}; expected 1 or more\n')
        return 2
    summary = notice.run_notice(out, gestures=tuple(args.gestures), sigmas=tuple(args.sigma),
                                seeds=args.seeds, progress=not args.quiet)
    path = out_dir_of(args, 'notice') / 'summary.json'
    common.write_json(path, summary)
    out.write(f'written: {path}\n')
    return 0


def register(bench_sub):
    """Add ``bench notice`` to the bench subcommands."""
    p = bench_sub.add_parser('notice', help='time to notice a hidden structure change, and '
                             'false alarms on the unchanged robot (simulated time)')
    p.add_argument('--gestures', nargs='+', default=['bye', 'circle'],
                   help='demo-library gestures to play (default bye circle)')
    p.add_argument('--sigma', nargs='+', type=float, default=[1.0, 4.0],
                   help='tracker noise per axis, mm (default 1 4)')
    p.add_argument('--seeds', type=int, default=3, help='noise seeds per case (default 3)')
    p.add_argument('--out', default=None, metavar='DIR',
                   help='output directory (default: bench_out/notice)')
    p.add_argument('--quiet', action='store_true', help='no progress lines')
    p.set_defaults(func=cmd_bench_notice)
