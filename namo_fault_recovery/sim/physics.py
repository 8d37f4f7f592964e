"""
Namo in MuJoCo: the URDF's arms with position actuators, stuck joints and self-contacts.

ROS-free, so that it can be tested and used without DDS; ``ros/sim_node.py`` wraps it.

The model is the generated URDF (:mod:`..model.urdf`) loaded by MuJoCo's URDF importer;
its collision geometry is then replaced by real capsules (MuJoCo has them, URDF does
not), the same capsules as the optimiser's self-collision model.

Choices, and why:

- Gravity is on and every arm body is gravity-compensated (``gravcomp``), as a real
  arm's controller does: the position actuators then track without a sag that would
  depend on the placeholder masses.
- Each joint has a position actuator with an implicit damping term (``kv``); the
  command is ``q_ref + kv / kp * qd_ref``, so the force is ``kp (q_ref - q) + kv
  (qd_ref - qd)``: a PD with velocity feed-forward, integrated by ``implicitfast``
  (stable at a 2 ms step with joint armature).
- A stuck joint is held by a joint equality constraint (the constraint solver holds it
  against everything the other joints do) and its actuator is commanded to the same
  angle; commands for it are ignored until it is released.
- Self-contacts: only the pairs the optimiser checks (each arm segment against the
  torso, each right-arm segment against each left-arm segment) are explicit MuJoCo
  contact pairs; adjacent links never touch by construction.  Contacts are physical.
  A contact counts when it is deeper than 1 mm (the objective's tolerance).
  *Designed contact*: where a two-handed reference gesture itself brings two capsules
  closer than their radii (the Wai palms pressed together: the wrists are 37.8 mm
  apart, two hand capsules need 50 mm), that depth is allowed, as in the optimiser's
  objective.  Such a pair is not a MuJoCo contact pair (a capsule is a round stand-in
  for a flat, soft palm: its contact force would push the pressed palms apart);
  MuJoCo measures its signed distance each step (``mj_geomDistance``) and it counts
  when deeper than the designed depth plus the tolerance.
- Readings: :meth:`NamoSim.positions` is the physics' exact state; :meth:`NamoSim.readings`
  is what an encoder reports, that state plus Gaussian noise of ``reading_noise`` rad
  (standard deviation, independent per joint and reading; 0 by default here,
  :meth:`NamoSim.set_reading_noise` sets it: the ``namo_sim`` node and ``bench
  detection-suite`` do), so that a detector is tried
  against readings that are not exact.
"""

from typing import NamedTuple

import mujoco
import numpy as np

from .profile_model import add_profile_capsules, is_profile_robot, MovingCapsules, profile_spec
from ..model.kinematics import arm_columns, forward_kinematics, shoulder_position
from ..model.robot import ARMS
from ..model.urdf import capsule_segments, SEGMENTS, urdf_string
from ..objective.collision import segment_distance

GRAVITY = (0.0, 0.0, -9.81)
# Reading noise (deg, standard deviation) of the simulated encoders: about one count
# of a 14-bit absolute encoder (0.022 deg), the order of a servo's position reading.
READING_NOISE_DEG = 0.02
CONTACT_TOLERANCE = 1e-3     # m of penetration tolerated, as the objective's 1 mm
ARMATURE = 0.05              # kg m^2 added to each actuated joint (a motor's rotor inertia)
DAMPING = 0.5                # N m s/rad of each actuated joint's own damping
_RGBA = {'right': (1.0, 0.55, 0.1, 1.0), 'left': (0.1, 0.6, 1.0, 1.0),
         'torso': (0.75, 0.75, 0.75, 1.0)}


def contact_pairs():
    """Return the checked capsule pairs as (name, name): arm-torso, then right-left."""
    pairs = [(f'{side}_arm_{seg}', 'torso') for side in ARMS for seg in SEGMENTS]
    pairs += [(f'right_arm_{a}', f'left_arm_{b}') for a in SEGMENTS for b in SEGMENTS]
    return pairs


def segments_mm(robot, q):
    """Return {capsule name: (start, end)} in mm in the base frame for both arms' angles."""
    out = {}
    for side, cols in arm_columns(robot).items():
        lm = forward_kinematics(robot, q[cols], side)
        ends = (shoulder_position(robot, side), lm.elbow, lm.wrist, lm.tip)
        for k, seg in enumerate(SEGMENTS):
            out[f'{side}_arm_{seg}'] = (ends[k], ends[k + 1])
    cap = robot.capsules
    out['torso'] = (np.array(cap.torso_top, float), np.array(cap.torso_bottom, float))
    return out


def designed_allowances(robot, library):
    """
    Return {pair: depth in m} by which two-handed reference gestures bring the arms together.

    Designed contact is the hands of a two-handed gesture meeting (the Wai palms
    pressed together): only right-left pairs of the library's two-handed gestures count,
    never the torso (no gesture is designed to go into it).  The depth of a pair is the
    deepest over those gestures' keyframes (the optimiser allows it per gesture; a
    simulator does not know which gesture is playing, so it allows the largest).  Only
    pairs with a positive depth appear.
    """
    cap = robot.capsules
    radius = {f'{side}_arm_{seg}': float(getattr(cap, seg)) for side in ARMS for seg in SEGMENTS}
    radius['torso'] = float(cap.torso_radius)
    out = {}
    for gesture in library:
        if not gesture.two_handed:
            continue
        for frame in gesture.keyframes:
            segs = segments_mm(robot, frame.positions())
            for a, b in contact_pairs():
                if b == 'torso':
                    continue
                dist = float(segment_distance(*segs[a], *segs[b])[0])
                depth = (radius[a] + radius[b] - dist) * 1e-3
                if depth > out.get((a, b), 0.0):
                    out[(a, b)] = depth
    return out


class Contact(NamedTuple):
    """One counted self-contact: the two capsules and its depth (m) beyond any design."""

    geom1: str
    geom2: str
    depth: float


def add_capsules(spec, robot, allowances):
    """
    Replace a model's URDF geometry by the self-collision capsules and their pairs.

    The URDF's cylinders and spheres go; each capsule of :func:`capsule_segments` is added
    to its link (collisions only through explicit pairs), and every checked pair that is
    not a designed contact (``allowances``) becomes a MuJoCo contact pair.
    """
    for geom in list(spec.geoms):
        spec.delete(geom)
    for cap in capsule_segments(robot):
        body = spec.body(cap.link) or spec.worldbody
        side = cap.name.split('_')[0]
        geom = body.add_geom(name=cap.name, type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                             fromto=np.concatenate((cap.start, cap.end)),
                             size=[cap.radius, 0.0, 0.0],
                             rgba=_RGBA.get(side, _RGBA['torso']))
        geom.contype = 0          # only the explicit pairs below collide
        geom.conaffinity = 0
    for a, b in contact_pairs():
        if (a, b) not in allowances:
            spec.add_pair(name=f'{a}-{b}', geomname1=a, geomname2=b)


def _spec(robot, urdf, allowances, joints):
    """
    Return the MjSpec of ``robot`` with its capsules and contact pairs.

    Namo: its generated URDF (or ``urdf``, the simulator's own copy: a change the
    planner does not know), rigid capsules.  A profile robot: its own URDF (or
    ``urdf``) through :func:`.profile_model.profile_spec`, moving capsules, ``joints``
    the ones that move.
    """
    if is_profile_robot(robot):
        spec = profile_spec(robot, urdf, joints)
        add_profile_capsules(spec, robot, contact_pairs(), allowances)
        return spec
    spec = mujoco.MjSpec.from_string(urdf or urdf_string(robot))
    add_capsules(spec, robot, allowances)
    return spec


class NamoSim:
    """
    The simulated robot: step it, command its actuators, stick joints, read contacts.

    Namo, or any two-armed robot from a URDF profile (:mod:`.profile_model`): its arm
    joints (``robot.joint_names``, in that order; with ``shared``, then the joints both
    arms hang from, ``robot.played_joints``: a torso) are actuated, every other joint is
    fixed.  Not thread-safe: the caller serialises access (the node holds one lock).
    """

    def __init__(self, robot, timestep=0.002, kp=300.0, kv=30.0, gravity=True,
                 allowances=None, tolerance=CONTACT_TOLERANCE, urdf=None, shared=False):
        if timestep <= 0 or kp <= 0 or kv < 0:
            raise ValueError('timestep and kp must be > 0 and kv >= 0')
        self.set_reading_noise(0.0)
        self.robot = robot
        self.joint_names = tuple(robot.played_joints if shared else robot.joint_names)
        self.kp, self.kv = float(kp), float(kv)
        self.allowances = dict(allowances or {})
        spec = _spec(robot, urdf, self.allowances, self.joint_names)
        spec.option.timestep = timestep
        spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        spec.option.gravity = GRAVITY if gravity else (0.0, 0.0, 0.0)
        for body in spec.bodies:
            if body.name != 'world':
                body.gravcomp = 1.0
        for name in self.joint_names:
            joint = spec.joint(name)
            joint.armature = ARMATURE
            joint.damping = [DAMPING, 0.0, 0.0]
            act = spec.add_actuator(name=name, target=name,
                                    trntype=mujoco.mjtTrn.mjTRN_JOINT)
            act.set_to_position(kp=kp, kv=kv)
            # A jammed actuator is rigid: the stiffest stable constraint (time constant
            # two steps) holds it within 0.02 deg of its angle while the arm moves, where
            # MuJoCo's default (0.02 s) let it swing 0.4 deg, and readings with it.
            spec.add_equality(name=f'stick_{name}', type=mujoco.mjtEq.mjEQ_JOINT,
                              name1=name, active=False, solref=[2.0 * timestep, 1.0])
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._moving = MovingCapsules(m, robot) if is_profile_robot(robot) else None
        self._qadr = np.array([m.jnt_qposadr[m.joint(n).id] for n in self.joint_names])
        self._dadr = np.array([m.jnt_dofadr[m.joint(n).id] for n in self.joint_names])
        self._act = np.array([m.actuator(n).id for n in self.joint_names])
        self._eq = np.array([m.equality(f'stick_{n}').id for n in self.joint_names])
        self._geom_names = [m.geom(i).name for i in range(m.ngeom)]
        self.tolerance = float(tolerance)
        self._designed = [(m.geom(a).id, m.geom(b).id, a, b, depth)
                          for (a, b), depth in self.allowances.items()]
        self._fromto = np.zeros(6)
        self.stuck = {}                 # joint name -> angle (rad)
        self.target = np.zeros(len(self.joint_names))
        self.target_velocity = np.zeros(len(self.joint_names))
        self.contact_steps = 0          # steps with at least one counted contact
        self.contact_events = 0         # pair contacts that began (onsets)
        self.max_depth = 0.0            # deepest counted penetration seen (m)
        self.pairs_seen = set()         # (geom, geom) of every counted contact since reset
        self._touching = set()
        self.set_positions(np.zeros(len(self.joint_names)))

    # --- state ---

    @property
    def time(self):
        """Return the simulated time, in seconds."""
        return float(self.data.time)

    @property
    def timestep(self):
        """Return the physics step, in seconds."""
        return float(self.model.opt.timestep)

    def positions(self):
        """Return the joint angles (rad), in ``joint_names`` order."""
        return self.data.qpos[self._qadr].copy()

    def set_reading_noise(self, std, seed=None):
        """Set the readings' noise: ``std`` rad (>= 0), from a generator seeded ``seed``."""
        if not std >= 0:
            raise ValueError(f'reading noise must be >= 0 rad, got {std}')
        self.reading_noise = float(std)
        self._rng = np.random.default_rng(seed)

    def readings(self):
        """Return the angles as the encoders read them: positions plus the noise."""
        q = self.positions()
        if self.reading_noise > 0:
            q += self._rng.normal(0.0, self.reading_noise, q.shape)
        return q

    def velocities(self):
        """Return the velocities of the joints, in rad/s."""
        return self.data.qvel[self._dadr].copy()

    def index(self, name):
        """Return the index of a joint name (KeyError naming the choices if unknown)."""
        try:
            return self.joint_names.index(name)
        except ValueError:
            raise KeyError(f'unknown joint {name!r}; expected one of '
                           f'{", ".join(self.joint_names)}') from None

    def set_positions(self, q):
        """Teleport the joints to ``q`` at rest and command them to stay there."""
        q = np.asarray(q, dtype=float)
        self.data.qpos[self._qadr] = q
        self.data.qvel[:] = 0.0
        self.set_targets(q, np.zeros_like(q))
        mujoco.mj_forward(self.model, self.data)
        if self._moving is not None:        # the capsules where the new pose has them
            self._moving.update(self.model, self.data)
            mujoco.mj_forward(self.model, self.data)

    def set_targets(self, q, qd=None):
        """Command the actuators to ``q`` (rad) at ``qd`` (rad/s); stuck joints ignore it."""
        q = np.asarray(q, dtype=float)
        qd = np.zeros_like(q) if qd is None else np.asarray(qd, dtype=float)
        self.target = q.copy()
        self.target_velocity = qd.copy()
        ctrl = q + (self.kv / self.kp) * qd
        for name, angle in self.stuck.items():
            ctrl[self.index(name)] = angle
        self.data.ctrl[self._act] = ctrl

    # --- stuck joints ---

    def stick(self, name, angle=None):
        """Make a joint stuck at ``angle`` (rad), or where it is now if None; return it."""
        i = self.index(name)
        if angle is None:
            angle = float(self.data.qpos[self._qadr[i]])
        angle = float(angle)
        if not np.isfinite(angle):
            raise ValueError(f'{name}: stuck angle must be finite, got {angle!r}')
        self.stuck[name] = angle
        self.model.eq_data[self._eq[i], 0] = angle      # polycoef[0]: q = angle
        self.model.eq_data[self._eq[i], 1:5] = 0.0
        self.data.eq_active[self._eq[i]] = 1
        self.data.ctrl[self._act[i]] = angle
        return angle

    def release(self, name):
        """Let a stuck joint follow commands again; return True if it was stuck."""
        i = self.index(name)
        self.data.eq_active[self._eq[i]] = 0
        return self.stuck.pop(name, None) is not None

    # --- stepping and contacts ---

    def step(self, n=1):
        """Advance the physics ``n`` steps, counting self-contacts after each."""
        for _ in range(n):
            if self._moving is not None:
                self._moving.update(self.model, self.data)
            mujoco.mj_step(self.model, self.data)
            touching = self._count()
            if touching:
                self.contact_steps += 1
            self.contact_events += len(touching - self._touching)
            self.pairs_seen |= touching
            self._touching = touching

    def contacts(self):
        """Return the counted contacts of now: deeper than the tolerance (and any design)."""
        out = []
        con = self.data.contact
        for k in range(self.data.ncon):
            depth = float(-con.dist[k])
            if depth > self.tolerance:
                out.append(Contact(self._geom_names[con.geom1[k]],
                                   self._geom_names[con.geom2[k]], depth))
        for id1, id2, a, b, designed in self._designed:
            dist = mujoco.mj_geomDistance(self.model, self.data, id1, id2, designed + 1.0,
                                          self._fromto)
            if -dist - designed > self.tolerance:
                out.append(Contact(a, b, float(-dist - designed)))
        return out

    def _count(self):
        touching = set()
        for contact in self.contacts():
            touching.add((contact.geom1, contact.geom2))
            self.max_depth = max(self.max_depth, contact.depth)
        return touching

    def reset_contact_count(self):
        """Zero the running contact counters."""
        self.contact_steps = 0
        self.contact_events = 0
        self.max_depth = 0.0
        self.pairs_seen = set()
