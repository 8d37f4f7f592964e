"""
A kinematic chain compiled from a URDF, base link to tip link: batched FK and Jacobians.

Why compile: a URDF chain is a list of fixed origins, each followed by a joint's rotation
about its own axis.  Evaluated as written, that is one dense 4x4 product per joint and
per configuration.  Compiling rewrites it once, at load time, into the cheapest form that
gives the same frames:

- every fixed joint is folded into the next joint's origin (and into the landmarks);
- a joint axis that is not +z is turned onto z by a constant rotation (a sign for -z);
- each origin rotation is split as ``RotZ(a) RotX(b) RotZ(c)``: ``RotZ(c)`` becomes an
  angle offset of this joint, ``RotZ(a)`` an angle offset of the previous one (its
  translation is re-expressed accordingly), so only ``RotX(b)`` remains: the modified
  DH form, with a general translation.  Entries within 1e-8 of 0 or +-1 are taken as
  exact (a URDF prints pi/2 as 1.57079633), so right-angle twists cost no products.

The forward pass then runs over the joints once for all N configurations (numpy
arrays of shape (N, 3) for the frame's columns and origin): there is no loop over
configurations.  Landmarks are frames fixed in chain links (with an optional offset);
their Jacobians are analytic, ``z_i x (p - o_i)`` for a revolute joint i.

Only revolute and continuous joints move a chain; a prismatic, floating, planar or
mimic joint between base and tip is refused with a one-line error naming the URDF and
the joint (:class:`ChainError`).
"""

from dataclasses import dataclass
import math

import numpy as np

from .kinematics import ArmJacobian, ArmLandmarks
from .rotations import cos_sin, rot_axis, rot_x_cs, rot_z
from .urdf_tree import UrdfTree
from ..errors import ConfigError

SNAP = 1e-8          # rotation entries this close to 0 or +-1 are taken as exact
LANDMARK_ROLES = ('elbow', 'wrist', 'tip', 'palm')


class ChainError(ConfigError):
    """A base-to-tip chain that the model cannot take (the message names the joint)."""


@dataclass(frozen=True)
class _Step:
    """One movable joint, compiled: translation, twist about x, then the joint's turn."""

    tx: float
    pre_y: float
    pre_z: float
    cb: float
    sb: float
    post_y: float
    post_z: float


def _snap(value):
    for exact in (0.0, 1.0, -1.0):
        if abs(value - exact) < SNAP:
            return exact
    return value


def _axis_frame(axis):
    """Return (A, sign): a rotation with ``A e_z = sign * axis``, sparse for +-x, +-y, +-z."""
    axis = np.array([_snap(v) for v in axis])
    for k, rot in ((2, np.eye(3)),
                   (0, np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])),
                   (1, np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]))):
        if abs(axis[k]) == 1.0:
            return rot, float(axis[k])
    turn = np.cross([0.0, 0.0, 1.0], axis)
    s, c = float(np.linalg.norm(turn)), float(axis[2])
    return rot_axis(turn / s, math.atan2(s, c)), 1.0


def _zxz(rot):
    """Return (a, cos b, sin b, c) with ``rot = RotZ(a) RotX(b) RotZ(c)`` (b snapped)."""
    sb = math.hypot(rot[0, 2], rot[1, 2])
    if sb > SNAP:
        a = math.atan2(rot[0, 2], -rot[1, 2])
        c = math.atan2(rot[2, 0], rot[2, 1])
        cb, sb = _snap(rot[2, 2]), _snap(sb)
        if cb == 0.0:
            sb = 1.0
        elif sb == 0.0:
            cb = math.copysign(1.0, cb)
        return a, cb, sb, c
    if rot[2, 2] > 0:
        return 0.0, 1.0, 0.0, math.atan2(rot[1, 0], rot[0, 0])
    return 0.0, -1.0, 0.0, math.atan2(-rot[1, 0], rot[0, 0])


def _clean(vec, tol):
    return tuple(0.0 if abs(v) < tol else float(v) for v in vec)


class ChainCompiler:
    """Fold a URDF path into steps; the state a link's frame is fixed in, and where."""

    def __init__(self, length_scale):
        self.scale = length_scale
        self.steps = []
        self.offsets = []
        self.signs = []
        self.init = None                # (R, p) of the state before the first turn
        self.link_frames = {}           # link -> [step index, 4x4 constant]
        self.acc = np.eye(4)            # the current link, relative to the last state

    def add_fixed(self, origin):
        """Fold one fixed origin (metres) into the running constant."""
        step = origin.copy()
        step[:3, 3] *= self.scale
        self.acc = self.acc @ step

    def add_joint(self, joint):
        """Compile one revolute or continuous joint after its origin."""
        self.add_fixed(joint.origin)
        frame, sign = _axis_frame(joint.axis)
        full = self.acc.copy()
        full[:3, :3] = full[:3, :3] @ frame
        a, cb, sb, c = _zxz(full[:3, :3])
        if not self.steps:
            self.init = (rot_z(a) @ rot_x_cs(cb, sb), full[:3, 3].copy())
            self.steps.append(_Step(0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0))
        else:
            self._fold_into_previous(a)
            self.steps.append(self._step(rot_z(-a) @ full[:3, 3], cb, sb))
        self.offsets.append(c)
        self.signs.append(sign)
        self.acc = np.eye(4)
        self.acc[:3, :3] = frame.T

    def _fold_into_previous(self, a):
        """Turn the previous state by ``RotZ(a)``: its offset grows, its links turn back."""
        self.offsets[-1] += a
        back = np.eye(4)
        back[:3, :3] = rot_z(-a)
        last = len(self.steps)
        for entry in self.link_frames.values():
            if entry[0] == last:
                entry[1] = back @ entry[1]

    def _step(self, t, cb, sb):
        tol = 1e-9 * self.scale
        tx, ty, tz = _clean(t, tol)
        u = rot_x_cs(cb, sb).T @ np.array([0.0, ty, tz])
        _, uy, uz = _clean(u, tol)
        if (ty != 0.0) + (tz != 0.0) < (uy != 0.0) + (uz != 0.0):
            return _Step(tx, ty, tz, cb, sb, 0.0, 0.0)
        return _Step(tx, 0.0, 0.0, cb, sb, uy, uz)

    def mark(self, link):
        """Record that ``link``'s frame is the running constant after the current state."""
        self.link_frames[link] = [len(self.steps), self.acc.copy()]


@dataclass(frozen=True)
class Landmark:
    """A frame fixed in a chain link: the state it moves with and its constant transform."""

    link: str
    state: int              # 0: the base; k: after the chain's k-th joint
    rot: np.ndarray | None  # (3, 3) relative to that state; None: the state's own
    pos: tuple              # (3,) relative to that state, in the chain's length unit


def _refuse(tree, joint, base, tip, where):
    what = f'mimics {joint.mimic!r}' if joint.mimic else f'is {joint.kind}'
    raise ChainError(tree.source, None,
                     f'{where + ": " if where else ""}joint {joint.name!r} on the chain '
                     f'{base} -> {tip} {what}; expected '
                     'revolute, continuous or fixed joints only (put the base link below it)')


def compile_chain(tree: UrdfTree, base: str, tip: str, landmarks: dict | None = None,
                  length_scale: float = 1.0, where: str = '',
                  locked: tuple = ()) -> 'KinematicChain':
    """
    Compile the chain ``base`` -> ``tip`` of ``tree``; raise ChainError if it cannot.

    ``landmarks`` maps a role (elbow, wrist, tip, palm or any name) to a link or to
    ``(link, offset)`` with the offset in metres in that link's frame; each link must be
    on the chain or fixed to one of its links.  ``length_scale`` converts metres to the
    chain's length unit (1000 for millimetres).  ``where`` prefixes the messages.
    The joints named in ``locked`` are held at 0 and folded like fixed joints (a
    reduced chain, as Pinocchio's ``buildReducedModel``): the chain moves only the
    others, at no cost for the held ones.
    """
    joints = tree.path(base, tip, where)
    compiler = ChainCompiler(length_scale)
    compiler.mark(base)
    for joint in joints:
        if joint.kind == 'fixed' or (joint.movable and joint.name in locked):
            compiler.add_fixed(joint.origin)
        elif joint.movable:
            compiler.add_joint(joint)
        else:
            _refuse(tree, joint, base, tip, where)
        compiler.mark(joint.child)
    movable = [j for j in joints if j.kind != 'fixed' and j.name not in locked]
    if not movable:
        raise ChainError(tree.source, None, f'{where + ": " if where else ""}the chain '
                         f'{base} -> {tip} has no revolute or continuous joint; expected '
                         'at least one')
    marks = {}
    for role, spec in (landmarks or {}).items():
        link, offset = spec if isinstance(spec, tuple) else (spec, (0.0, 0.0, 0.0))
        marks[role] = _landmark(tree, compiler, link, offset, length_scale, where)
    return KinematicChain(tree.name, base, tip, tuple(j.name for j in movable),
                          np.array([j.lower for j in movable]),
                          np.array([j.upper for j in movable]),
                          tuple(j.velocity for j in movable), compiler, marks)


def _landmark(tree, compiler, link, offset, length_scale, where):
    """Return the Landmark of ``link`` (+ offset), fixed in a link of the chain."""
    tree.require_link(link, where)
    fixed = np.eye(4)
    while link not in compiler.link_frames:
        joint = tree.parent_joint.get(link)
        if joint is None or joint.kind != 'fixed':
            moved = f'joint {joint.name!r} moves it' if joint else 'it is above the base'
            raise ChainError(tree.source, None,
                             f'{where + ": " if where else ""}link {link!r} is not fixed to '
                             f'the chain {compiler_ends(compiler)} ({moved}); expected a link '
                             'of the chain or one fixed to it')
        step = joint.origin.copy()
        step[:3, 3] *= length_scale
        fixed = step @ fixed
        link = joint.parent
    state, const = compiler.link_frames[link]
    total = const @ fixed
    pos = total[:3, :3] @ (np.asarray(offset, dtype=float) * length_scale) + total[:3, 3]
    rot = np.vectorize(_snap)(total[:3, :3])
    rot = None if np.array_equal(rot, np.eye(3)) else rot
    return Landmark(link, state, rot, _clean(pos, 1e-9 * length_scale))


def compiler_ends(compiler):
    """Return 'first -> last' of the links a compiler has marked (for messages)."""
    names = list(compiler.link_frames)
    return f'{names[0]} -> {names[-1]}'


def _mix(cols, coeffs):
    """Return sum_k coeffs[k] * cols[k], skipping zero coefficients and unit products."""
    out = None
    for col, k in zip(cols, coeffs):
        if k == 0.0:
            continue
        term = col if k == 1.0 else (-col if k == -1.0 else k * col)
        out = term if out is None else out + term
    return out if out is not None else np.zeros_like(cols[0])


class KinematicChain:
    """
    One compiled base-to-tip chain: joint names and limits, batched FK and Jacobians.

    ``q`` has shape (N, n_joints), radians, in :attr:`joint_names` order (base first).
    Lengths are in the unit the chain was compiled for.
    """

    def __init__(self, robot, base, tip, joint_names, lower, upper, velocity, compiler,
                 landmarks):
        self.robot, self.base, self.tip = robot, base, tip
        self.joint_names = joint_names
        self.lower, self.upper = lower, upper
        self.velocity = velocity            # rad/s per joint; None where the URDF has none
        self.landmarks = landmarks          # role -> Landmark
        self._steps = tuple(compiler.steps)
        self._offsets = np.array(compiler.offsets)
        signs = np.array(compiler.signs)
        self._signs = None if np.all(signs == 1.0) else signs
        rot, pos = compiler.init
        self._init = (tuple(rot[:, k].copy() for k in range(3)), pos.copy())
        self._frames = {link: (s, c) for link, (s, c) in compiler.link_frames.items()}

    def __repr__(self):
        """Return the chain as its constants: the same text for the same chain in any process."""
        return (f'KinematicChain({self.base!r}, {self.tip!r}, {tuple(self.joint_names)!r}, '
                f'{self.describe()!r})')

    def describe(self) -> tuple:
        """Return the compiled constants (steps, offsets, signs, landmarks) as plain data."""
        rounded = (lambda a: tuple(np.round(np.asarray(a, dtype=float), 9).ravel().tolist()))
        marks = tuple((role, m.link, m.state, None if m.rot is None else rounded(m.rot),
                       rounded(m.pos)) for role, m in sorted(self.landmarks.items()))
        steps = tuple(tuple(round(v, 9) for v in vars(st).values()) for st in self._steps)
        return (steps, rounded(self._offsets),
                None if self._signs is None else rounded(self._signs),
                rounded(self._init[1]), tuple(rounded(c) for c in self._init[0]),
                rounded(self.lower), rounded(self.upper), marks)

    @property
    def n_joints(self) -> int:
        """Return the number of revolute/continuous joints from base to tip."""
        return len(self.joint_names)

    def _states(self, q, keep=None):
        """
        Return, per state 0..n, ``(origin, x, y, z)``: arrays of shape (N, 3) or (3,).

        With ``keep`` (a set of state indices), the other states are None: a batch then
        holds only the frames it reads, not all n + 1 of them (a smaller working set; a
        few per cent of Namo's FK time at most, within the noise of ``bench fk``).
        """
        theta = q * self._signs + self._offsets if self._signs is not None else \
            q + self._offsets
        cos_t, sin_t = (a.T[:, :, None] for a in cos_sin(theta))
        eye = np.eye(3)
        states = [(np.zeros(3), eye[0], eye[1], eye[2])]
        (x, y, z), pos = self._init
        every = keep is None
        for i, st in enumerate(self._steps):
            if i:
                if st.tx:
                    pos = pos + st.tx * x
                if st.pre_y:
                    pos = pos + st.pre_y * y
                if st.pre_z:
                    pos = pos + st.pre_z * z
                if st.cb == 0.0:        # a right-angle twist: no products
                    y, z = (z, -y) if st.sb == 1.0 else (-z, y)
                elif st.cb == -1.0:
                    y, z = -y, -z
                elif st.cb != 1.0:
                    y, z = st.cb * y + st.sb * z, st.cb * z - st.sb * y
                if st.post_y:
                    pos = pos + st.post_y * y
            c, s = cos_t[i], sin_t[i]
            x, y = c * x + s * y, c * y - s * x
            if st.post_z:
                pos = pos + st.post_z * z
            states.append((pos, x, y, z) if every or i + 1 in keep else None)
        return states

    @staticmethod
    def _point(state, offset, n):
        pos, x, y, z = state
        point = pos
        for col, k in zip((x, y, z), offset):
            if k:
                point = point + k * col
        return point if point.shape == (n, 3) else np.broadcast_to(point, (n, 3))

    @staticmethod
    def _rotation(state, rot, n):
        _, x, y, z = state
        if rot is None:
            cols = (x, y, z)
        else:
            cols = [_mix((x, y, z), rot[:, k]) for k in range(3)]
        if any(c.shape != (n, 3) for c in cols):
            cols = [np.broadcast_to(c, (n, 3)) for c in cols]
        return np.stack(cols, axis=-1)

    def check(self, q, name='q') -> np.ndarray:
        """Return ``q`` as a finite float array (..., n_joints), or raise ValueError."""
        arr = np.asarray(q, dtype=float)
        if arr.ndim == 0 or arr.shape[-1] != self.n_joints:
            raise ValueError(f'{name}: expected joint angles of shape (..., {self.n_joints}) '
                             f'for {", ".join(self.joint_names)}; got shape {arr.shape}')
        if not np.all(np.isfinite(arr)):
            raise ValueError(f'{name}: joint angles must be finite')
        return arr

    def forward(self, q) -> ArmLandmarks:
        """Return the elbow, wrist, tip positions and palm rotation for ``q`` (..., n)."""
        q = self.check(q)
        lead = q.shape[:-1]
        lm = self.batch_forward(q.reshape(-1, self.n_joints))
        return ArmLandmarks(*(a.reshape(lead + a.shape[1:]) for a in lm))

    def batch_forward(self, q) -> ArmLandmarks:
        """:meth:`forward` on a checked (N, n) array, for callers that validated q."""
        keep = {mark.state for mark in self.landmarks.values()}
        return self._landmarks_of(self._states(q, keep), q.shape[0])

    def _landmarks_of(self, states, n):
        marks = self.landmarks
        if not all(r in marks for r in LANDMARK_ROLES):
            raise ValueError(f'chain {self.base} -> {self.tip}: expected landmarks '
                             f'{", ".join(LANDMARK_ROLES)}; has {", ".join(marks) or "none"}')
        points = [self._point(states[marks[r].state], marks[r].pos, n)
                  for r in LANDMARK_ROLES[:3]]
        palm = marks['palm']
        return ArmLandmarks(*points, self._rotation(states[palm.state], palm.rot, n))

    def frame_states(self) -> dict:
        """Return {link: (state, 4x4 constant)}: the chain links and what carries each."""
        return dict(self._frames)

    def link_frames(self, q, links=None) -> dict:
        """Return {link: (origin (N, 3), rotation (N, 3, 3))} of chain links (all: None)."""
        q = np.atleast_2d(self.check(q))
        states = self._states(q)
        n = q.shape[0]
        out = {}
        for link in links if links is not None else self._frames:
            state, const = self._frames[link]
            out[link] = (self._point(states[state], const[:3, 3], n),
                         self._rotation(states[state], const[:3, :3], n))
        return out

    def jacobian(self, q) -> tuple[ArmLandmarks, ArmJacobian]:
        """
        Return ``(landmarks, jacobian)`` for q (N, n) in one vectorised pass.

        ``jacobian.positions`` (N, 3, n, 3): d(elbow, wrist, tip) / dq_i, zero for
        joints downstream of a landmark; ``jacobian.axes`` (N, n, 3): the angular
        velocity of the palm per unit dq_i (zero downstream of the palm's link).
        """
        q = np.atleast_2d(self.check(q))
        states = self._states(q)
        n, m = q.shape
        lm = self._landmarks_of(states, n)
        # Filled joint by joint: a state may be one (3,) row for every pose (a joint
        # before the first moving one), and stacking broadcast views cost more here
        # than the Jacobian's arithmetic (TIAGo++'s keyframe search).
        axes, origins = np.empty((n, m, 3)), np.empty((n, m, 3))
        for i in range(m):
            origins[:, i], axes[:, i] = states[i + 1][0], states[i + 1][3]
        if self._signs is not None:
            axes = axes * self._signs[:, None]
        pts = np.stack((lm.elbow, lm.wrist, lm.tip), axis=1)
        arm = pts[:, :, None, :] - origins[:, None]                    # (N, 3, n, 3)
        ax = axes[:, None]
        jac = np.empty_like(arm)    # z_i x (p - o_i), written out: np.cross is slower here
        jac[..., 0] = ax[..., 1] * arm[..., 2] - ax[..., 2] * arm[..., 1]
        jac[..., 1] = ax[..., 2] * arm[..., 0] - ax[..., 0] * arm[..., 2]
        jac[..., 2] = ax[..., 0] * arm[..., 1] - ax[..., 1] * arm[..., 0]
        reach = np.array([self.landmarks[r].state for r in LANDMARK_ROLES[:3]])
        jac[:, np.arange(m)[None, :] >= reach[:, None]] = 0.0
        palm_axes = axes.copy()
        palm_axes[:, np.arange(m) >= self.landmarks['palm'].state] = 0.0
        return lm, ArmJacobian(jac, palm_axes)
