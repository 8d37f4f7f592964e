"""
One motion explored on the robot: typical points, an explorer, Kriging to every point.

:func:`explore_motion` runs one explorer (``secant``: ours, ``annealing``: the paper's)
at a motion's typical points (:func:`~namo_fault_recovery.recovery.vq.quantise`, through
:func:`~namo_fault_recovery.recovery.motion.typical_points`), then spreads the
corrections to every point by ordinary Kriging
(:class:`~namo_fault_recovery.recovery.kriging.OrdinaryKriging`), as the paper does.
The paper's correction is r = theta'' - theta; ours is taken relative to the corrected
model's own inverse kinematics at every point, warm-started from the paper's Kriging so
that it stays on the explored poses' branch (the fitted structure is the trend, and
Kriging spreads what the measurements still said beyond it).  With every point as a
typical point (``every_point``) nothing is interpolated: the paper's upper bound.

The result, an :class:`ExploredMotion`, has origin ``explored`` and is scored by what the
tracker measured at the typical points, not by the model.
"""

from dataclasses import dataclass, field

import numpy as np

from .annealing import AnnealingSchedule, explore_annealing
from .corrections import solve_poses
from .secant import explore_secant, SecantOptions
from .task import DEFAULT_EXPANSION_MM, ExploreTask
from .trial import TrialSession
from ..recovery.keyframes import locked_sets
from ..recovery.kriging import OrdinaryKriging
from ..recovery.motion import expansion_layouts

METHODS = ('secant', 'annealing')
ORIGIN = 'explored'


@dataclass
class ExploredMotion:
    """One motion adapted by exploration on the robot: poses, cost and measured error."""

    name: str
    method: str
    q: np.ndarray                   # (T, n) rad: the adapted arm poses, locks applied
    typical: tuple                  # indices of the typical points
    trials_per_point: tuple         # trials commanded at each typical point
    trials: int                     # all trials commanded (refused poses are not)
    robot_seconds: float            # move + settle + tracker latency, summed
    measured_error_mm: tuple        # at each typical point's final pose, as measured
    stage: int                      # DOF expansion stage reached
    free_joints: tuple              # joint names free at that stage
    correction: str = ''            # the structural correction ours found, described
    model: object = None            # that correction (.corrections.Correction: groups, params)
    status: str = 'converged'
    origin: str = ORIGIN
    kriging_sigma_deg: tuple = ()
    notes: list = field(default_factory=list)

    @property
    def measured_mean_mm(self) -> float:
        """Return the mean measured fingertip error at the typical points (the score)."""
        return float(np.mean(self.measured_error_mm))


def motion_layouts(robot, gesture, side, locks):
    """
    Return ``((stage, joint indices), ...)``: the designed DOF and each expansion stage.

    The free joints of ``side`` as :func:`~namo_fault_recovery.recovery.motion.expansion_layouts`
    gives them (the gesture's designed joints, or all, less the locked ones).
    """
    arm = robot.arms[side]
    free = gesture.joints or arm.joint_names
    passes = expansion_layouts(robot, gesture, locked_sets(robot, locks), {side}, free, 0)
    return tuple((stage, np.array([j for s, j in lay if s == side], dtype=int))
                 for stage, lay in passes)


def make_task(chain, design, picks, locks, layouts, sigma_mm,
              expansion_mm=DEFAULT_EXPANSION_MM):
    """
    Return the ExploreTask of a motion's typical points ``picks``.

    ``design`` (T, n) rad is the arm's designed motion; its fingertip path on the
    nominal ``chain`` is the target; ``locks`` maps arm joint indices to lock angles.
    """
    design = np.asarray(design, dtype=float)
    start = locked(design[list(picks)], locks)
    targets = chain.batch_forward(design[list(picks)]).tip
    return ExploreTask(chain, start, targets, chain.lower, chain.upper, tuple(layouts),
                       float(sigma_mm), expansion_mm, tuple(int(p) for p in picks))


def locked(q, locks):
    """Return ``q`` with the locked joints (index -> angle) at their angles."""
    q = np.array(q, dtype=float)
    for j, angle in locks.items():
        q[..., j] = angle
    return q


def spread(design, picks, solved, trend=None):
    """
    Return every point's pose (T, n) and Kriging sigma (deg): the corrections spread.

    The correction at a typical point is ``solved - trend`` there (``trend`` None: the
    design, the paper's r = theta'' - theta); Kriging in the designed joint space (deg)
    gives it at every point, added to the trend.
    """
    design = np.asarray(design, dtype=float)
    base = design if trend is None else np.asarray(trend, dtype=float)
    picks = list(picks)
    if len(picks) == len(design):
        return np.array(solved, dtype=float), ()
    r = np.degrees(np.asarray(solved) - base[picks])
    x = np.degrees(design)
    est = OrdinaryKriging(x[picks], r).predict(x)
    out = base + np.radians(est.values)
    out[picks] = solved
    return out, tuple(float(s) for s in np.sqrt(est.variance))


@dataclass(frozen=True)
class MotionSpec:
    """One arm's motion to explore: its design, typical points, locks and layouts."""

    name: str
    chain: object               # the nominal KinematicChain (mm)
    design: np.ndarray          # (T, n) rad
    picks: tuple                # typical point indices
    locks: dict                 # arm joint index -> lock angle (rad)
    layouts: tuple              # see :func:`motion_layouts`
    joint_names: tuple = ()


def explore_motion(session: TrialSession, spec: MotionSpec, method: str = 'secant',
                   sigma_mm: float = 1.0, options=None, seed: int = 0) -> 'ExploredMotion':
    """
    Explore one motion of one arm on ``session``'s robot; return its ExploredMotion.

    ``options`` is the explorer's (:class:`~.secant.SecantOptions` or
    :class:`~.annealing.AnnealingSchedule`; None: the defaults); ``sigma_mm`` the
    tracker's declared noise.
    """
    if method not in METHODS:
        raise ValueError(f'explore method {method!r}; expected one of {", ".join(METHODS)}')
    name, chain, design, picks = spec.name, spec.chain, spec.design, spec.picks
    locks, joint_names = spec.locks, spec.joint_names
    task = make_task(chain, design, picks, locks, spec.layouts, sigma_mm)
    trials0, seconds0 = session.trials, session.seconds
    if method == 'secant':
        found = explore_secant(session, task, options or SecantOptions())
    else:
        found = explore_annealing(session, task, options or AnnealingSchedule(), seed)
    trend = None
    if found.model is not None:
        # The corrected model's IK at every point, warm-started from (and drawn to) the
        # paper's Kriging of the explored poses, so that it stays on their branch.
        design_all = np.asarray(design, dtype=float)
        warm = np.clip(locked(spread(design_all, picks, found.q)[0], locks), chain.lower,
                       chain.upper)
        trend, _ = solve_poses(lambda q, idx: found.model.tip(q), warm,
                               chain.batch_forward(design_all).tip, np.asarray(found.free),
                               chain.lower, chain.upper, warm,
                               keep_clear=session.safety.keep_clear())
    q, sigma = spread(design, picks, found.q, trend)
    q = np.clip(locked(q, locks), chain.lower, chain.upper)
    names = tuple(joint_names[j] for j in found.free) if joint_names else found.free
    return ExploredMotion(
        name=name, method=method, q=q, typical=tuple(int(p) for p in picks),
        trials_per_point=tuple(int(t) for t in found.trials),
        trials=int(session.trials - trials0), robot_seconds=float(session.seconds - seconds0),
        measured_error_mm=tuple(float(e) for e in found.measured_error(task.targets)),
        stage=int(found.stage), free_joints=names, correction=found.correction,
        model=found.model,
        status=found.status, kriging_sigma_deg=sigma, notes=list(found.notes))
