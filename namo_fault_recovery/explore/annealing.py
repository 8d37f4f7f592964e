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
"""

from dataclasses import dataclass

import numpy as np

from .task import ExploreTask, PointOutcome
from .trial import recording_end, TrialSession, UnsafeTrial


@dataclass(frozen=True)
class AnnealingSchedule:
    """The SA schedule: trials per point and stage, start temperature and step, cooling."""

    trials_per_stage: int = 150
    temperature_mm: float = 10.0     # start temperature of the Metropolis rule (mm)
    step_deg: float = 4.0            # start step (std of the Gaussian move, deg)
    final_ratio: float = 1e-3        # T_end / T_start over one stage's trials
    stop_mm: float = 0.0             # a measured error below this ends the point early

    def describe(self) -> str:
        """Return the schedule as the README states it."""
        return (f'{self.trials_per_stage} trials per point and stage, T0 '
                f'{self.temperature_mm:g} mm, step {self.step_deg:g} deg x sqrt(T/T0), '
                f'geometric cooling to {self.final_ratio:g} T0')


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


def explore_annealing(session: TrialSession, task: ExploreTask,
                      schedule: AnnealingSchedule = AnnealingSchedule(),
                      seed: int = 0) -> PointOutcome:
    """Explore ``task``'s typical points by the paper's SA; return what was measured."""
    rng = np.random.default_rng(seed)
    k = len(task.start)
    out = PointOutcome(np.array(task.start, dtype=float), np.zeros((k, 3)),
                       np.zeros(k, dtype=int))
    with recording_end(out):
        for p in range(k):
            q = out.q[p]
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
