"""
The paper's explorer: simulated annealing on the measured fingertip error, per point.

The second source paper explores each typical point by simulated annealing (Kirkpatrick
et al.) on the changed robot, without a model: a candidate is the current pose plus a
Gaussian step in the free joints, it is commanded and measured, and it is accepted by
the Metropolis rule on the measured error at a temperature that cools geometrically.
The pose with the lowest measured error is kept.  The step shrinks with the square
root of the temperature.  When a point's best error stays above the expansion threshold
after the designed DOF, the next stage's joints are freed and the search goes on from
the best pose, with the same schedule.  Trials are counted: the paper did not count
them ("about 8 % exploration cost" counts points).

The paper does not say where each point's SA starts.  Its literal reading (``start``
``design``) starts every point at its designed pose; after an expansion that frees more
joints than the target needs (a redundant arm), the points' solutions then lie on
different branches and the Kriging of r = theta'' - theta between them is meaningless.
A robot exploring point after point can instead carry on in the motion's order
(``previous``, ``kriging``): each point starts at its designed pose plus the
correction r found at the point before it, or the Kriging of those found so far, so
that the solutions stay on one branch.  Either way only measured errors guide it.
"""

from dataclasses import dataclass

import numpy as np

from .task import ExploreTask, PointOutcome
from .trial import recording_end, TrialSession, UnsafeTrial
from ..recovery.kriging import OrdinaryKriging

# 'design': every typical point starts at its designed pose (the paper's reading);
# 'previous': the points are explored in the motion's order and each starts at its
# designed pose plus the previous explored point's r = theta'' - theta; 'kriging': plus
# the Kriging of r over the points explored so far, at its designed pose.
START_POSES = ('design', 'previous', 'kriging')


def check_start(how: str, what: str) -> None:
    """Raise ValueError (one line naming ``what``) unless ``how`` is one of START_POSES."""
    if how not in START_POSES:
        raise ValueError(f'{what}: expected one of {", ".join(START_POSES)}, got {how!r}')


@dataclass(frozen=True)
class AnnealingSchedule:
    """The SA schedule: trials per point and stage, start temperature and step, cooling."""

    trials_per_stage: int = 150
    temperature_mm: float = 10.0     # start temperature of the Metropolis rule (mm)
    step_deg: float = 4.0            # start step (std of the Gaussian move, deg)
    final_ratio: float = 1e-3        # T_end / T_start over one stage's trials
    stop_mm: float = 0.0             # a measured error below this ends the point early
    start: str = 'design'            # where each point's SA starts: see START_POSES

    def __post_init__(self):
        check_start(self.start, 'SA schedule start')

    def describe(self) -> str:
        """Return the schedule as the README states it."""
        return (f'{self.trials_per_stage} trials per point and stage, T0 '
                f'{self.temperature_mm:g} mm, step {self.step_deg:g} deg x sqrt(T/T0), '
                f'geometric cooling to {self.final_ratio:g} T0, start: {self.start}')


def _anneal_point(session, task, p, q0, free, schedule, rng):
    """Anneal one point from ``q0``; return (best q, best measured tip, trials)."""
    target = task.targets[p]
    pid = task.point_ids[p] if task.point_ids else p
    trial = session.trial(q0, pid)
    cur_q, cur_e = q0.copy(), float(np.linalg.norm(trial.tip - target))
    best = (cur_q.copy(), trial.tip.copy(), cur_e)
    n = schedule.trials_per_stage
    alpha = schedule.final_ratio ** (1.0 / max(n - 1, 1))
    temp, used = schedule.temperature_mm, 1
    while used < n and best[2] > schedule.stop_mm:
        scale = np.radians(schedule.step_deg) * np.sqrt(temp / schedule.temperature_mm)
        cand = cur_q.copy()
        cand[free] += rng.normal(0.0, scale, len(free))
        cand = np.clip(cand, task.lower, task.upper)
        try:
            trial = session.trial(cand, pid)
        except UnsafeTrial:
            temp *= alpha          # refused without moving: counts as a step of the schedule
            continue
        used += 1
        err = float(np.linalg.norm(trial.tip - target))
        if err < cur_e or rng.random() < np.exp(-(err - cur_e) / max(temp, 1e-12)):
            cur_q, cur_e = cand, err
        if err < best[2]:
            best = (cand.copy(), trial.tip.copy(), err)
        temp *= alpha
    return best, used


# A carried-on start the safety checks refuse is pulled back toward the point before's
# explored pose (already commanded safely) by these fractions of the way to it.
_PULL_BACK = (1.0, 0.5, 0.25, 0.125, 0.0)


def start_pose(session: TrialSession, task: ExploreTask, explored: np.ndarray, p: int,
               how: str) -> np.ndarray:
    """
    Return where point ``p``'s SA starts: its designed pose, or carried on from before.

    ``explored`` (K, n) holds the poses found at the points before ``p`` (the motion's
    order).  ``how`` is one of :data:`START_POSES`: ``previous`` adds r(p - 1) to the
    designed pose, ``kriging`` the Kriging of the r found so far (in the designed joint
    space, deg, as :func:`.motion.spread`), so that the solutions stay on one branch.
    A carried-on start the checks refuse (it would collide: the branch of one point
    need not clear the torso at the next) is pulled back toward the point before's
    explored pose rather than sent back to the design, which would restart the search
    on any branch; the design remains if even that is refused.
    """
    check_start(how, 'SA start')
    design = np.asarray(task.start, dtype=float)
    if how == 'design' or p == 0:
        return design[p].copy()
    r = explored[:p] - design[:p]
    if how == 'previous' or p == 1:
        shift = r[-1]
    else:
        x = np.degrees(design)
        shift = np.radians(OrdinaryKriging(x[:p], np.degrees(r)).predict(x[p:p + 1]).values[0])
    carried = np.clip(design[p] + shift, task.lower, task.upper)
    before = explored[p - 1]
    for frac in _PULL_BACK:
        q = before + frac * (carried - before)
        if not session.problem(q):
            return q
    return design[p].copy()


def explore_annealing(session: TrialSession, task: ExploreTask,
                      schedule: AnnealingSchedule = AnnealingSchedule(),
                      seed: int = 0) -> PointOutcome:
    """
    Explore ``task``'s typical points by the paper's SA; return what was measured.

    The points are explored in the task's order (the motion's), each from the pose
    ``schedule.start`` gives (:func:`start_pose`).
    """
    rng = np.random.default_rng(seed)
    k = len(task.start)
    out = PointOutcome(np.array(task.start, dtype=float), np.zeros((k, 3)),
                       np.zeros(k, dtype=int))
    with recording_end(out):
        for p in range(k):
            q = start_pose(session, task, out.q, p, schedule.start)
            for stage, free in task.layouts:
                before = session.trials
                (q, tip, err), _ = _anneal_point(session, task, p, q,
                                                 np.asarray(free, int), schedule, rng)
                out.trials[p] += session.trials - before
                out.q[p], out.measured[p] = q, tip
                out.stage = max(out.stage, stage)
                out.free = tuple(int(j) for j in free) if stage >= out.stage else out.free
                if err <= task.expansion_mm:
                    break
    return out
