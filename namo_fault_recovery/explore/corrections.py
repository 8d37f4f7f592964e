"""
Structural corrections of the nominal model, fitted to measured fingertips (ours).

One structural error explains every typical point, so the measurements of all of them
are fitted together.  The nominal chain (any robot's
:class:`~namo_fault_recovery.model.chain.KinematicChain`) is the prior; a correction is
a small set of groups of parameters, each one kind of change a fall or a user leaves:

- ``tip_offset``: a vector (mm) added to the fingertip in the tip link's frame: a tool,
  a longer or shorter hand;
- ``offset:JOINT``: the joint's true angle is its reading plus this (deg): a slipped
  encoder;
- ``bend:LINK``: a rotation vector (deg) of everything beyond ``LINK``'s frame, about that
  frame's origin, in that frame: a bent link (and a link length change at the tip end).

Which groups the measurements support is chosen by forward selection on the Bayesian
information criterion (chi-square at the tracker's noise plus k ln m), so that noise is
not fitted as structure; every parameter also has a Gaussian prior (regularisation).
:func:`solve_poses` is the batched damped least-squares inverse kinematics on a
corrected model, with a per-point bias and a per-point secant (Broyden) Jacobian term.
"""

from dataclasses import dataclass
from functools import lru_cache
import math

import numpy as np
from scipy.optimize import least_squares

from ..model.rotations import rotation_vectors

PRIOR = {'tip_offset': 100.0, 'offset': 10.0, 'bend': 10.0}   # prior std: mm, deg, deg
SIZES = {'tip_offset': 3, 'offset': 1, 'bend': 3}
MAX_GROUPS = 2
CLEAR_WEIGHT = 10.0     # mm of tip error per mm of clearance short of the margin (solve_poses)
SOLVE_ITERATIONS = 40   # solve_poses: damped least-squares iterations
SOLVE_MAX_STEP = 0.3    # rad: its longest step of a joint per iteration


@dataclass(frozen=True)
class Correction:
    """A corrected model: the nominal chain plus named groups of parameters."""

    chain: object
    groups: tuple = ()          # group names, e.g. ('tip_offset', 'offset:right_arm_joint2')
    params: tuple = ()          # one tuple of values per group (mm or deg)

    def describe(self) -> str:
        """Return the groups and values, e.g. ``tip_offset (0.1, 0.0, 49.8) mm``."""
        if not self.groups:
            return 'none (the nominal model explains the measurements)'
        unit = {'tip_offset': 'mm', 'offset': 'deg', 'bend': 'deg'}
        return '; '.join(f'{g} ({", ".join(f"{v:.2f}" for v in p)}) {unit[g.split(":")[0]]}'
                         for g, p in zip(self.groups, self.params))

    def tip(self, q):
        """Return where the corrected model puts the fingertip, in mm, at readings ``q`` rad."""
        return corrected_tip(self.chain, self.groups, self.params, q)


def corrected_tip(chain, groups, params, q):
    """Return the fingertip (N, 3) mm of ``chain`` with the correction groups applied."""
    q = np.array(np.atleast_2d(q), dtype=float)
    names = list(chain.joint_names)
    bends, tip_offset = [], None
    for group, values in zip(groups, params):
        kind, _, where = group.partition(':')
        if kind == 'offset':
            q[:, names.index(where)] += math.radians(values[0])
        elif kind == 'tip_offset':
            tip_offset = np.asarray(values, dtype=float)
        else:
            bends.append((where, np.radians(np.asarray(values, dtype=float))))
    tip = chain.batch_forward(q).tip
    links = [chain.tip] + [b[0] for b in bends]
    frames = chain.link_frames(q, links)
    if tip_offset is not None:
        tip = tip + frames[chain.tip][1] @ tip_offset
    order = {link: i for i, link in enumerate(chain_links(chain))}
    for link, w in sorted(bends, key=lambda b: -order[b[0]]):     # distal first
        origin, rot = frames[link]
        turn = rot @ rotation_vectors(np.broadcast_to(w, (len(q), 3))) @ np.swapaxes(rot, 1, 2)
        tip = origin + np.einsum('nij,nj->ni', turn, tip - origin)
    return tip


@lru_cache(maxsize=16)
def chain_links(chain):
    """Return the chain's link names, base first (a chain's links never change)."""
    return tuple(chain.link_frames(np.zeros((1, chain.n_joints))).keys())


def candidate_groups(chain):
    """Return every correction group the selection may use on ``chain``."""
    links = list(chain_links(chain))[1:-1]            # a bend of the base or the tip moves nothing
    return (['tip_offset'] + [f'offset:{j}' for j in chain.joint_names]
            + [f'bend:{link}' for link in links])


def _unpack(groups, x):
    out, i = [], 0
    for g in groups:
        n = SIZES[g.split(':')[0]]
        out.append(tuple(float(v) for v in x[i:i + n]))
        i += n
    return tuple(out)


def fit(chain, groups, q, y, sigma, x0=None):
    """Fit ``groups`` to measurements (q (M, n) rad, y (M, 3) mm); return (Correction, chi2)."""
    groups = tuple(groups)
    prior = np.concatenate([[PRIOR[g.split(':')[0]]] * SIZES[g.split(':')[0]]
                            for g in groups]) if groups else np.zeros(0)

    def residual(x):
        params = _unpack(groups, x)
        r = (corrected_tip(chain, groups, params, q) - y).ravel() / sigma
        return np.concatenate((r, x / prior))

    if not groups:
        r = residual(np.zeros(0))
        return Correction(chain), float(r @ r)
    start = np.zeros(len(prior)) if x0 is None else np.asarray(x0, dtype=float)
    out = least_squares(residual, start, method='lm', x_scale=prior, xtol=1e-10)
    return Correction(chain, groups, _unpack(groups, out.x)), float(2 * out.cost)


def select(chain, q, y, sigma, max_groups=MAX_GROUPS, candidates=None):
    """
    Return the Correction the measurements support: forward selection on BIC.

    BIC = chi2 + k ln m (k parameters, m scalar measurements); a group is added while it
    lowers BIC, at most ``max_groups``.
    """
    q, y = np.atleast_2d(q), np.atleast_2d(y)
    m = y.size
    best, chi2 = fit(chain, (), q, y, sigma)
    best_bic = chi2
    pool = list(candidates or candidate_groups(chain))
    for _ in range(max_groups):
        trial = None
        for g in pool:
            if g in best.groups:
                continue
            groups = best.groups + (g,)
            x0 = np.concatenate([np.asarray(p) for p in best.params]
                                + [np.zeros(SIZES[g.split(':')[0]])])
            cand, c2 = fit(chain, groups, q, y, sigma, x0)
            k = len(x0)
            bic = c2 + k * math.log(m)
            if trial is None or bic < trial[0]:
                trial = (bic, cand)
        if trial is None or trial[0] >= best_bic:
            break
        best_bic, best = trial
    return best


def solve_poses(tip_fn, q0, targets, free, lower, upper, anchor, stay=2.0, keep_clear=None):
    """
    Damped least squares IK for K points at once; return (q (K, n), error (K,) mm).

    ``tip_fn(q, idx)`` returns the model's tip (N, 3) for poses q (N, n) of points
    ``idx`` (N,) (so each point may carry its own bias and secant term).  Only the
    joint indices ``free`` move, within [lower, upper]; ``stay`` (mm per rad) draws
    them to ``anchor`` (K, n), which picks one solution of a redundant arm.  With
    ``keep_clear`` = ``(clearance, margin)`` (``clearance(q)``: (N, n) -> (N,) mm, as
    :func:`.safety.capsule_clearance`), every millimetre of clearance below ``margin``
    costs :data:`CLEAR_WEIGHT` mm of tip error: the IK keeps out of the body.
    """
    iters, max_step = SOLVE_ITERATIONS, SOLVE_MAX_STEP
    q = np.clip(np.array(q0, dtype=float), lower, upper)
    k, nf = len(q), len(free)
    idx = np.arange(k)
    lam = np.full(k, 1e-2)
    eps = 1e-6

    def residuals(x, rows):
        r = tip_fn(x, rows) - targets[rows]
        if keep_clear is None:
            return r
        inside = np.maximum(keep_clear[1] - keep_clear[0](x), 0.0)
        return np.concatenate((r, CLEAR_WEIGHT * inside[:, None]), axis=1)

    def cost(x):
        r = residuals(x, idx)
        d = (x - anchor)[:, free]
        return np.sum(r * r, axis=1) + stay ** 2 * np.sum(d * d, axis=1), r

    c, r = cost(q)
    if nf == 0:
        return q, np.sqrt(np.sum(r[:, :3] * r[:, :3], axis=1))
    for _ in range(iters):
        probe = np.repeat(q[:, None], nf, axis=1)
        probe[:, np.arange(nf), free] += eps
        jac = (residuals(probe.reshape(-1, q.shape[1]), np.repeat(idx, nf)).reshape(
            k, nf, r.shape[1]) - r[:, None]) / eps                  # (K, nf, 3 or 4)
        jtj = np.einsum('kia,kja->kij', jac, jac) + stay ** 2 * np.eye(nf)[None]
        grad = np.einsum('kia,ka->ki', jac, r) + stay ** 2 * (q - anchor)[:, free]
        damped = jtj + lam[:, None, None] * np.eye(nf)[None]
        step = -np.linalg.solve(damped, grad[..., None])[..., 0]
        step *= np.minimum(1.0, max_step / np.maximum(np.abs(step).max(axis=1), 1e-12))[:, None]
        trial = q.copy()
        trial[:, free] += step
        trial = np.clip(trial, lower, upper)
        c_new, r_new = cost(trial)
        better = c_new < c
        q[better], r[better], c[better] = trial[better], r_new[better], c_new[better]
        lam = np.where(better, lam * 0.3, lam * 10.0)
        if np.all(np.abs(step).max(axis=1) < 1e-7):
            break
    return q, np.sqrt(np.sum(r[:, :3] * r[:, :3], axis=1))
