"""
A template recovery profile guessed from a URDF's kinematic tree and link names.

Why guess: a robot team should start from a profile that loads, then correct it, not
from a blank page.  The guesses, each reported with its reason:

- **arms**: serial runs of 5 or more revolute joints (more than 8, which the model does
  not take, are reported) that leave a branching link (a torso, a base), not named like
  a leg, wheel or head, and stopped by the first joint named like a hand's (gripper,
  finger, thumb ...) or by the next branching;
- **side**: ``left`` / ``right`` in the names, else the sign of y of the first joint;
- **base and shared joints**: from the link the arms leave, up through the revolute
  joints above it that both arms share (a torso or waist); those are the shared and the
  staged-expansion joints;
- **tip**: the best-named link fixed below the arm (grasp, tcp, fingertip, tip ... then
  palm, hand, gripper, tool), else the last link;
- **landmarks**: links or joints named elbow and wrist; otherwise from the geometry at
  the zero pose: consecutive joints whose origins coincide form groups (shoulder, elbow,
  wrist), the elbow is the first link of the middle group and the wrist that of the
  last; the palm is a link named palm fixed below the arm, else the last arm link.

What it cannot know (the fingertip offset, a missing velocity limit, an arm it could
not find) it says, and writes a value that a person must check.
"""

from dataclasses import dataclass, field
import json
import re
import textwrap

import numpy as np

from .chain import compile_chain
from .urdf_tree import UrdfTree

ARM_JOINTS = (5, 8)
HAND_JOINT_WORDS = ('gripper', 'hand', 'finger', 'thumb', 'index', 'middle', 'ring',
                    'little', 'pinky', 'claw', 'jaw')
NOT_ARM_WORDS = ('leg', 'foot', 'ankle', 'knee', 'hip', 'wheel', 'caster', 'head', 'neck',
                 'suspension', 'eye', 'camera')
TIP_WORDS = (('grasp', 'tcp', 'fingertip', 'tip', 'end_effector', 'eef'),
             ('palm', 'hand', 'gripper', 'tool'))


@dataclass
class Template:
    """A guessed profile (YAML text) with what was guessed and what could not be."""

    text: str = ''
    guessed: list = field(default_factory=list)
    missing: list = field(default_factory=list)


def _tokens(name):
    return [t for t in re.split(r'[^a-z]+', name.lower()) if t]


def named(name, words):
    """Return True if a token of ``name`` is, starts or ends with one of ``words``."""
    return any(t == w or t.startswith(w) or (len(w) > 2 and t.endswith(w))
               for t in _tokens(name) for w in words)


def _active(joint):
    return joint.kind != 'fixed' and joint.mimic is None


class _Tree:
    """The tree's child lists and, per link, whether joints below it move."""

    def __init__(self, tree: UrdfTree):
        self.tree = tree
        self.kids = {link: tree.children(link) for link in tree.links}
        self.moves = {}
        for link in reversed(self._order()):
            self.moves[link] = any(_active(j) or self.moves[j.child] for j in self.kids[link])

    def _order(self):
        order, todo = [], [self.tree.root]
        while todo:
            link = todo.pop()
            order.append(link)
            todo.extend(j.child for j in self.kids[link])
        return order

    def moving_kids(self, link):
        """Return the child joints of ``link`` with a moving joint at or below them."""
        return [j for j in self.kids[link] if _active(j) or self.moves[j.child]]

    def fixed_below(self, link):
        """Return ``link`` and the links fixed below it, depth first."""
        out, todo = [], [link]
        while todo:
            here = todo.pop(0)
            out.append(here)
            todo.extend(j.child for j in self.kids[here] if j.kind == 'fixed')
        return out


def _walk(t, first):
    """Return the serial run of joints from ``first`` on, and the link it ends at."""
    run, link = [first], first.child
    while True:
        kids = t.moving_kids(link)
        if len(kids) != 1:
            return run, link
        joint = kids[0]
        if _active(joint):
            if named(joint.name, HAND_JOINT_WORDS) or named(joint.child, HAND_JOINT_WORDS):
                return run, link
            run.append(joint)
        link = joint.child


def _first_moving(t, joint):
    """
    Return the first joint at or below ``joint`` that is not fixed, through fixed ones.

    An arm may hang from its branch by a fixed mount (Baxter's ``right_torso_arm_mount``
    before ``right_s0``).  None if the fixed joints branch again before one moves (that
    link is a branch of its own, and is searched as one).
    """
    while joint.kind == 'fixed':
        kids = t.moving_kids(joint.child)
        if len(kids) != 1:
            return None
        joint = kids[0]
    return joint


def find_arms(t):
    """Return [(branch link, [arm joints])] of every serial run that looks like an arm."""
    arms = []
    for link in t.tree.links:
        kids = t.moving_kids(link)
        if len(kids) < 2 and link != t.tree.root:
            continue
        for first in kids:
            first = _first_moving(t, first)
            if first is None or not _active(first) or \
                    first.kind not in ('revolute', 'continuous'):
                continue
            run, _ = _walk(t, first)
            names = [j.name for j in run] + [j.child for j in run]
            if (ARM_JOINTS[0] <= len(run)
                    and all(j.kind in ('revolute', 'continuous') for j in run)
                    and not any(named(n, NOT_ARM_WORDS) for n in names)):
                arms.append((link, run))
    return arms


def _torso(t, branch):
    """
    Return (base link, joints, blocker) walking up from ``branch`` through revolute joints.

    ``blocker`` is the first joint above that a chain cannot take (prismatic, mimic ...),
    or None if the walk reached the root.
    """
    joints, link, base = [], branch, branch
    while link in t.tree.parent_joint:
        joint = t.tree.parent_joint[link]
        if joint.kind != 'fixed' and not joint.movable:
            return base, joints, joint
        if joint.movable:
            joints.insert(0, joint)
            base = joint.parent
        link = joint.parent
    return base, joints, None


def _side(run, frames):
    names = ' '.join(_tokens(' '.join(j.name for j in run)))
    for side, words in (('left', ('left', 'l')), ('right', ('right', 'r'))):
        if any(w in names.split() for w in words):
            return side, f'"{side}" in its joint names'
    y = frames[run[0].child][0][0, 1]
    return ('left' if y > 0 else 'right'), f'its first joint is at y = {y:+.3f} m'


def _groups(run, frames):
    """Group consecutive arm links whose origins coincide at the zero pose."""
    points = [frames[j.child][0][0] for j in run]
    length = sum(float(np.linalg.norm(b - a)) for a, b in zip(points, points[1:]))
    tol = max(0.005, 0.02 * length)
    groups = [[0]]
    for i in range(1, len(run)):
        if np.linalg.norm(points[i] - points[groups[-1][0]]) < tol:
            groups[-1].append(i)
        else:
            groups.append([i])
    return groups, points


def _elbow_wrist(run, frames, report, side):
    """Return (elbow link, wrist link) from the names, else from the geometry."""
    found = {}
    for role in ('elbow', 'wrist'):
        for joint in run:
            if named(joint.name, (role,)) or named(joint.child, (role,)):
                found[role] = joint.child
                report.guessed.append(f'{side} {role}: {joint.child} (named like a {role})')
                break
    groups, points = _groups(run, frames)
    shape = ' | '.join(' '.join(str(i + 1) for i in g) for g in groups)
    if 'wrist' not in found:
        found['wrist'] = run[groups[-1][0]].child
        ok = len(groups) > 1
        (report.guessed if ok else report.missing).append(
            f'{side} wrist: {found["wrist"]} (first link of the last group of coinciding '
            f'joint origins at the zero pose: joints {shape}){"" if ok else "; check it"}')
    if 'elbow' not in found:
        middle = groups[1:-1]
        if middle:
            arc = np.cumsum([0.0] + [float(np.linalg.norm(b - a))
                                     for a, b in zip(points, points[1:])])
            half = arc[-1] / 2
            best = min(middle, key=lambda g: abs(arc[g[0]] - half))
            found['elbow'] = run[best[0]].child
            report.guessed.append(f'{side} elbow: {found["elbow"]} (first link of the middle '
                                  f'group of joint origins: joints {shape})')
        else:
            found['elbow'] = run[len(run) // 2].child
            report.missing.append(f'{side} elbow: no link named elbow and no middle group of '
                                  f'joint origins (joints {shape}); wrote {found["elbow"]}, '
                                  'check it')
    return found['elbow'], found['wrist']


def _hand(t, run, report, side):
    """Return (tip link, palm link) fixed below the arm's last link."""
    last = run[-1].child
    below = t.fixed_below(last)
    tip = None
    for tier, words in enumerate(TIP_WORDS):
        tip = next((link for link in below if named(link, words)), None)
        if tip is not None:
            report.guessed.append(f'{side} tip: {tip} (named like {"/".join(words)})')
            break
    if tip is None:
        tip = below[-1]
        report.missing.append(f'{side} tip: no link named like a hand or tool below {last}; '
                              f'wrote {tip}, check it')
    report.missing.append(f'{side} fingertip offset: unknown; wrote [0, 0, 0] m in {tip}')
    palm = next((link for link in below if named(link, ('palm',))), None)
    if palm is None:
        palm = last
        report.guessed.append(f'{side} palm: {palm} (the last arm link; no link named palm)')
    else:
        report.guessed.append(f'{side} palm: {palm} (named like a palm)')
    return tip, palm


def _name(text):
    return text if re.fullmatch(r'[A-Za-z0-9_./-]+', text) else json.dumps(text)


def _names(names, indent=0):
    """Return a YAML flow list, wrapped under 90 columns after ``indent`` characters."""
    text = '[' + ', '.join(_name(n) for n in names) + ']'
    if indent + len(text) <= 90:
        return text
    return textwrap.fill(text, 90, initial_indent=' ' * indent,
                         subsequent_indent=' ' * (indent + 1))[indent:]


def _comment(line):
    return textwrap.wrap(line, 90, initial_indent='#   - ', subsequent_indent='#       ')


def _arm_entry(t, branch, run, report):
    """Return (side, entry dict) of one found arm."""
    base, torso, blocker = _torso(t, branch)
    if blocker is not None:
        note = (f'{blocker.name} above {base} is {blocker.kind}'
                f'{" (a mimic)" if blocker.mimic else ""}: a chain cannot take it, so the '
                f'arms start at {base}')
        if note not in report.missing:
            report.missing.append(note)
    chain = compile_chain(t.tree, base, run[-1].child)
    frames = chain.link_frames(np.zeros(chain.n_joints))
    side, why = _side(run, frames)
    report.guessed.append(f'{side} arm: {run[0].name} .. {run[-1].name} ({len(run)} joints '
                          f'from {branch}; {why})')
    if len(run) > ARM_JOINTS[1]:
        report.missing.append(f'{side} arm: {len(run)} joints; the model takes '
                              f'{ARM_JOINTS[0]} to {ARM_JOINTS[1]}: keep some in joints')
    elbow, wrist = _elbow_wrist(run, frames, report, side)
    tip, palm = _hand(t, run, report, side)
    return side, {'base': base, 'tip': tip, 'elbow': elbow, 'wrist': wrist, 'palm': palm,
                  'joints': [j.name for j in run], 'expansion': [j.name for j in torso]}


def _arms(t, report):
    """Return {side: entry} of the arms found (at most one per side)."""
    arms = {}
    for branch, run in find_arms(t):
        side, entry = _arm_entry(t, branch, run, report)
        if side in arms:
            report.missing.append(f'{side} arm: a second candidate {run[0].name} .. '
                                  f'{run[-1].name} left out; keep the one you mean')
            continue
        arms[side] = entry
    if not arms:
        report.missing.append('arms: no serial run of 5 or more revolute joints that looks '
                              'like an arm; write arms.right (and arms.left) by hand')
    return arms


def _lines(tree, urdf_ref, arms, shared, velocity, report):
    out = [f'# Recovery profile of {tree.name!r}, a template guessed by '
           '`namo-recovery profile`', f'# from {tree.source}.', '# Guessed:']
    out += [c for g in report.guessed for c in _comment(g)] + ['# Could not (check these):']
    out += [c for m in report.missing for c in _comment(m)] or ['#   (nothing)']
    out += [f'name: {_name(tree.name)}', f'urdf: {_name(urdf_ref)}',
            f'shared: {_names(shared)}']
    if velocity:
        out.append('velocity_limits:   # rad/s: the URDF gives none')
        out += [f'  {_name(j)}: null' for j in velocity]
    else:
        out.append('velocity_limits: {}')
    out.append('arms:' if arms else 'arms: {}')
    for side, arm in sorted(arms.items(), key=lambda kv: kv[0] != 'right'):
        out += [f'  {side}:', f'    base: {_name(arm["base"])}', f'    tip: {_name(arm["tip"])}',
                '    landmarks:', f'      elbow: {_name(arm["elbow"])}',
                f'      wrist: {_name(arm["wrist"])}',
                f'      fingertip: {{link: {_name(arm["tip"])}, offset: [0.0, 0.0, 0.0]}}',
                f'      palm: {_name(arm["palm"])}',
                f'    joints: {_names(arm["joints"], len("    joints: "))}',
                f'    expansion: {_names(arm["expansion"], len("    expansion: "))}']
    return out


def guess_profile(tree: UrdfTree, urdf_ref: str) -> Template:
    """
    Return a template profile for ``tree`` (its ``urdf`` key is ``urdf_ref``).

    The template's ``guessed`` and ``missing`` lists say what was guessed, and why, and
    what could not be; both are also the comments at the top of its text.
    """
    report = Template()
    arms = _arms(_Tree(tree), report)
    owners = {}
    for side, arm in arms.items():
        for name in arm['expansion']:
            owners.setdefault(name, []).append(side)
    shared = [name for name, sides in owners.items() if len(sides) > 1]
    if shared:
        report.guessed.append(f'shared (and staged-expansion): {", ".join(shared)} (revolute '
                              'joints above both arms)')
    velocity = []
    for arm in arms.values():
        for name in arm['joints'] + arm['expansion']:
            if tree.joints[name].velocity is None and name not in velocity:
                velocity.append(name)
    if velocity:
        report.missing.append(f'velocity limits of {", ".join(velocity)}: none in the URDF; '
                              'wrote null, give rad/s')
    report.text = '\n'.join(_lines(tree, urdf_ref, arms, shared, velocity, report)) + '\n'
    return report
