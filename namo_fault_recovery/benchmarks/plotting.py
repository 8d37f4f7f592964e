"""
Figures: 3D stick figures of reference and reconfigured arms, and benchmark box plots.

matplotlib is an optional extra (``pip install matplotlib`` or ``pip install
'namo_fault_recovery[plot]'``).  It is imported only when a figure is drawn, and only
its object-oriented API with the Agg canvas is used, so nothing here touches the
pyplot state or needs a display.  Without matplotlib every drawing function raises
:class:`MatplotlibMissing`, whose message says how to install it.
"""

import math
from pathlib import Path

import numpy as np

from ..model.kinematics import forward_kinematics, shoulder_position

REFERENCE_COLOR = 'tab:blue'
RECONFIGURED_COLOR = 'tab:orange'
PALM_NORMAL_MM = 60.0
INSTALL_HINT = ('matplotlib is not installed; install it with `pip install matplotlib` or '
                "`pip install 'namo_fault_recovery[plot]'`")


class MatplotlibMissing(ImportError):
    """matplotlib, an optional extra, is needed for this figure."""


def figure(figsize):
    """Return a new Figure on an Agg canvas (no pyplot, no display needed)."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
        import mpl_toolkits.mplot3d  # noqa: F401  (registers the 3d projection)
    except ImportError as exc:
        raise MatplotlibMissing(INSTALL_HINT) from exc
    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig


def arm_points(robot, q, side):
    """
    Return the stick figure of one arm: shoulder, elbow, wrist, fingertip (4, 3) mm.

    Also returns the palm normal, a unit vector at the palm.  [reading] The palm faces
    along -z of frame 7: in Wai this makes the two palms face each other.
    """
    lm = forward_kinematics(robot, np.asarray(q, dtype=float), side)
    pts = np.stack((shoulder_position(robot, side), lm.elbow, lm.wrist, lm.tip))
    normal = -lm.palm[:, 2]
    return pts, normal


def _draw_arm(axes, robot, q, side, color, label, style='-'):
    pts, normal = arm_points(robot, q, side)
    palm = 0.5 * (pts[2] + pts[3])
    tip = palm + PALM_NORMAL_MM * normal
    ax3, front, side_view = axes
    ax3.plot(pts[:, 0], pts[:, 1], pts[:, 2], style, color=color, lw=2.5, marker='o',
             ms=4, label=label)
    ax3.plot([palm[0], tip[0]], [palm[1], tip[1]], [palm[2], tip[2]], '-', color=color,
             lw=1.2, alpha=0.8)
    for ax, (u, v) in ((front, (1, 2)), (side_view, (0, 2))):
        ax.plot(pts[:, u], pts[:, v], style, color=color, lw=2.5, marker='o', ms=4,
                label=label)
        ax.annotate('', xy=(tip[u], tip[v]), xytext=(palm[u], palm[v]),
                    arrowprops={'arrowstyle': '->', 'color': color, 'lw': 1.2})
    return np.vstack((pts, tip[None]))


def _label_views(ax3, front, side_view):
    """Label the 3D, front and side views of a stick figure."""
    ax3.set_xlabel('x (mm, forward)')
    ax3.set_ylabel('y (mm, left)')
    ax3.set_zlabel('z (mm, up)')
    ax3.view_init(elev=15, azim=30)
    front.set_title('front view (y-z)', fontsize=10)
    front.set_xlabel('y (mm, robot left)')
    front.set_ylabel('z (mm)')
    side_view.set_title('side view (x-z)', fontsize=10)
    side_view.set_xlabel('x (mm, forward)')
    side_view.set_ylabel('z (mm)')
    for ax in (front, side_view):
        ax.set_aspect('equal', adjustable='datalim')
        ax.grid(True, alpha=0.3)
    ax3.legend(loc='upper left', fontsize=8)


def plot_reconfiguration(robot, library, report, gesture, path, keyframe=0, title=None,
                         dpi=120):
    """
    Draw the reference (blue) and reconfigured (orange) arms of one gesture to ``path``.

    ``report`` is a :class:`~namo_fault_recovery.recovery.result.LibraryResult` holding
    ``gesture``.  Every arm the gesture uses is drawn (both for Wai) as a stick
    figure shoulder-elbow-wrist-fingertip with its palm normal (a thin line or arrow
    from the middle of the hand), in 3D and in front (y-z) and side (x-z) views, in the
    style of the paper's Figs. 5 and 7.  Returns the path written.
    """
    ref = library[gesture]
    result = report[gesture]
    if not 0 <= keyframe < len(ref.keyframes):
        raise ValueError(f'keyframe: gesture {gesture} has keyframes '
                         f'0..{len(ref.keyframes) - 1}, got {keyframe}')
    fig = figure((14.0, 5.2))
    grid = fig.add_gridspec(1, 3, width_ratios=(1.4, 1.0, 1.0))
    ax3 = fig.add_subplot(grid[0], projection='3d')
    front = fig.add_subplot(grid[1])
    side_view = fig.add_subplot(grid[2])
    axes = (ax3, front, side_view)
    ref_kf, new_kf = ref.keyframes[keyframe], result.keyframes[keyframe]
    everything = []
    for side in ref.arms:
        first = side == ref.arms[0]
        everything.append(_draw_arm(axes, robot, ref_kf.arm(side), side, REFERENCE_COLOR,
                                    'reference' if first else None))
        everything.append(_draw_arm(axes, robot, new_kf.arm(side), side, RECONFIGURED_COLOR,
                                    'reconfigured' if first else None, '--'))
    shoulders = np.stack([shoulder_position(robot, s) for s in ('right', 'left')])
    for ax, (u, v) in ((front, (1, 2)), (side_view, (0, 2))):
        ax.plot(shoulders[:, u], shoulders[:, v], '-', color='0.6', lw=4)
    ax3.plot(shoulders[:, 0], shoulders[:, 1], shoulders[:, 2], '-', color='0.6', lw=4)
    pts = np.vstack(everything + [shoulders])
    _equal_3d(ax3, pts)
    _label_views(ax3, front, side_view)
    if title is None:
        locks = ', '.join(f'{j} = {math.degrees(a):.2f} deg' for j, a in report.locks.items())
        title = (f'{gesture}: {locks} locked; score {result.score_before:.3f} -> '
                 f"{result.score_after:.3f} ({report.settings.get('optimizer', '?')}, "
                 f'{result.status}, '
                 f'{1000 * result.wall_time:.0f} ms)')
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    return path


def plot_motion(robot, gesture, adaptation, path, dpi=110):
    """
    Draw a motion's fingertip paths in 3D: desired, unadapted and adapted.

    The colours follow the second source paper's Fig. 5-7: the desired path in green,
    the unadapted motion on the changed structure as red dots, the adapted motion in
    blue with its explored typical points as circles.  ``adaptation`` is the
    :class:`~namo_fault_recovery.recovery.result.LibraryResult` holding the motion.
    """
    fig = figure((7.5, 6.5))
    ax = fig.add_subplot(projection='3d')
    side = gesture.arms[0]
    col = slice(0, 7) if side == 'right' else slice(7, 14)
    model = robot.with_tool(adaptation.tool_mm, adaptation.tool_arm)
    design = gesture.joint_matrix()[:, col]
    g = adaptation[gesture.name]
    adapted = np.array([kf.arm(side) for kf in g.keyframes])
    unadapted = design.copy()
    for joint, angle in adaptation.locks.items():
        arm, j = robot.locate_joint(joint)
        if arm == side:
            unadapted[:, j] = angle
    want = forward_kinematics(robot, design, side).tip
    before = forward_kinematics(model, unadapted, side).tip
    after = forward_kinematics(model, adapted, side).tip
    ax.plot(*want.T, color='tab:green', lw=2.5, label='desired (designed motion)')
    ax.plot(*before.T, 'o', color='tab:red', ms=2.5,
            label=f'unadapted (mean error {g.tip_error_before_mm:.0f} mm)')
    ax.plot(*after.T, color='tab:blue', lw=1.5,
            label=f'adapted, {g.method} (mean error {g.tip_error_mm:.1f} mm)')
    if g.method == 'kriging':
        typ = after[list(g.typical_indices)]
        ax.plot(*typ.T, 'o', mfc='none', color='tab:blue', ms=8,
                label=f'{len(g.typical_indices)} explored typical points')
    ax.set_xlabel('x (mm)')
    ax.set_ylabel('y (mm)')
    ax.set_zlabel('z (mm)')
    change = [f'{j} locked at {math.degrees(a):.0f} deg' for j, a in adaptation.locks.items()]
    if adaptation.tool_mm:
        change.append(f'{adaptation.tool_mm:g} mm tool')
    ax.set_title(f'{gesture.name}: {", ".join(change)}', fontsize=10)
    _equal_3d(ax, np.concatenate((want, before, after)))
    ax.legend(loc='upper left', fontsize=8)
    path = Path(path)
    fig.savefig(path, dpi=dpi, bbox_inches='tight')
    return path


def _equal_3d(ax, pts):
    """Give a 3D axes equal scales around the points."""
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    centre = 0.5 * (lo + hi)
    half = 0.5 * float(np.max(hi - lo)) + 20.0
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1, 1, 1))
    from matplotlib.ticker import MaxNLocator
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(nbins=5))


def boxplot_paper(runs, keys, cases, out_dir, labels=None, dpi=100, optima=None):
    """
    Draw the paper benchmark's box plots; return the paths written.

    ``runs[(key, gesture, joint)]`` is a list of run dicts with ``score`` and ``time``.
    One ``scores_<gesture>.png`` per gesture (a panel per failed joint, a box per
    algorithm) and one ``times.png`` (a panel per gesture, times pooled over joints).
    ``optima`` maps ``(gesture, joint)`` to the best-known optimum, drawn as a dashed line.
    """
    labels = labels or {k: k for k in keys}
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    gestures = list(dict.fromkeys(g for g, _ in cases))
    written = []
    for g in gestures:
        joints = [j for gg, j in cases if gg == g]
        fig = figure((2.6 * len(joints) + 1.0, 4.2))
        for n, j in enumerate(joints):
            ax = fig.add_subplot(1, len(joints), n + 1)
            data = [[r['score'] for r in runs[(k, g, j)]] for k in keys]
            ax.boxplot(data, showfliers=True)
            if optima and (g, j) in optima:
                ax.axhline(optima[(g, j)], ls='--', lw=1, color='tab:green',
                           label='best-known optimum')
                if n == 0:
                    ax.legend(fontsize=7, loc='upper right')
            ax.set_xticks(range(1, len(keys) + 1))
            ax.set_xticklabels([labels[k] for k in keys], rotation=60, fontsize=7)
            ax.set_title(j.replace('right_arm_', ''), fontsize=9)
            ax.grid(True, axis='y', alpha=0.3)
            if n == 0:
                ax.set_ylabel('score (lower is better)')
        fig.suptitle(f'{g}: scores per failed right-arm joint', fontsize=10)
        fig.tight_layout()
        path = out_dir / f'scores_{g}.png'
        fig.savefig(path, dpi=dpi)
        written.append(path)
    fig = figure((3.2 * len(gestures) + 1.0, 4.2))
    for n, g in enumerate(gestures):
        ax = fig.add_subplot(1, len(gestures), n + 1)
        data = [[r['time'] for (k2, g2, _), rs in runs.items() if k2 == k and g2 == g
                 for r in rs] for k in keys]
        ax.boxplot(data, showfliers=True)
        ax.set_xticks(range(1, len(keys) + 1))
        ax.set_xticklabels([labels[k] for k in keys], rotation=60, fontsize=7)
        ax.set_yscale('log')
        ax.set_title(g, fontsize=9)
        ax.grid(True, axis='y', alpha=0.3)
        if n == 0:
            ax.set_ylabel('wall time per gesture (s)')
    fig.suptitle('computation time, all failed joints pooled', fontsize=10)
    fig.tight_layout()
    path = out_dir / 'times.png'
    fig.savefig(path, dpi=dpi)
    written.append(path)
    return written


def _deg(q):
    return '[' + ', '.join(f'{x:7.2f}' for x in np.degrees(q)) + ']'


def plot_gesture(out, robot, library, name, faults, settings, path, *, seed, deadline,
                 keyframe=0):
    """
    Recover gesture ``name`` (locked as the whole library would be), draw it, print figures.

    The ``plot`` command: a single pose is drawn as arm skeletons
    (:func:`plot_reconfiguration`), a motion as fingertip paths (:func:`plot_motion`).
    Raises ValueError for settings the engine rejects.
    """
    from .common import run_recover
    gesture = library[name]
    result = run_recover(robot, library, faults, settings, seed=seed, deadline=deadline,
                         gestures=[name])
    g = result[name]
    for joint, angle in result.locks.items():
        out.write(f'lock {joint} = {math.degrees(angle):.2f} deg\n')
    if len(gesture.keyframes) > 1:
        plot_motion(robot, gesture, result, path)
        out.write(f'{g.message}\n  fingertip error (mm): unadapted mean '
                  f'{g.tip_error_before_mm:.1f}; adapted mean {g.tip_error_mm:.1f}, max '
                  f'{g.tip_error_max_mm:.1f}; {g.nfev} evaluations, '
                  f'{1000 * result.wall_time:.0f} ms\n')
        for note in result.notes:
            out.write(f'  note: {note}\n')
        out.write(f'written: {path}\n')
        return result
    plot_reconfiguration(robot, library, result, name, path, keyframe=keyframe)
    kf = g.keyframes[keyframe]
    out.write(f'{name}: score {g.score_before:.4f} -> {g.score_after:.4f} '
              f'({settings.optimizer}, {g.status}, {1000 * g.wall_time:.1f} ms)\n')
    for side in gesture.arms:
        out.write(f'  {side:5s} reference    (deg) '
                  f'{_deg(gesture.keyframes[keyframe].arm(side))}\n')
        out.write(f'  {side:5s} reconfigured (deg) {_deg(kf.arm(side))}\n')
    out.write(f'written: {path}\n')
    return result
