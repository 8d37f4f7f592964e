"""Figure of one play: commanded and measured joint angles over time (matplotlib)."""

import math

import numpy as np


def plot_play(path, names, commands, measured, title='', locks=None):
    """
    Draw commanded (dashed) and measured (solid) angles of every joint that moved.

    ``commands`` is a list of ``(t, {joint: angle})`` samples of the sent trajectory
    points, ``measured`` a list of ``(t, {joint: angle})`` joint states, both in seconds
    from the start of the play and rad; ``locks`` marks locked joints.  Saves ``path``.
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    locks = locks or {}
    moved = []
    for joint in names:
        seen = [s[joint] for _, s in commands if joint in s]
        seen += [s[joint] for _, s in measured if joint in s]
        if joint in locks or (seen and np.ptp(seen) > math.radians(1.0)):
            moved.append(joint)
    rows = max(1, math.ceil(len(moved) / 2))
    fig, axes = plt.subplots(rows, 2, figsize=(11, 2.0 * rows + 0.8), sharex=True,
                             squeeze=False)
    for ax, joint in zip(axes.ravel(), moved):
        for samples, style, label in ((commands, '--', 'commanded'),
                                      (measured, '-', 'measured')):
            pts = [(t, s[joint]) for t, s in samples if joint in s]
            if pts:
                t, q = zip(*pts)
                ax.plot(t, np.degrees(q), style, label=label)
        if joint in locks:
            ax.axhline(math.degrees(locks[joint]), color='red', lw=0.8,
                       label=f'lock {math.degrees(locks[joint]):.1f} deg')
        ax.set_title(joint, fontsize=9)
        ax.set_ylabel('deg')
        ax.legend(fontsize=7, loc='best')
    for ax in axes.ravel()[len(moved):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel('s from the play request')
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return moved
