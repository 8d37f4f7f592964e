"""
The gesture library as a play_motion2 motions file (no ROS).

PAL's play_motion2 reads its motions from the parameters of its node::

    play_motion2:
      ros__parameters:
        controllers: [right_arm_controller, left_arm_controller]
        motions:
          wai:
            joints: [right_arm_joint1, ...]
            positions: [...]           # keyframes flattened, len = joints x times
            times_from_start: [2.0]
            meta: {name: Wai, usage: gesture, description: '...'}

so a library reconfigured for the current faults can be played by play_motion2 too.
"""

import math

import numpy as np
import yaml

DEFAULT_CONTROLLERS = ('right_arm_controller', 'left_arm_controller')


def motions_document(motions, descriptions=None, locks=None,
                     controllers=DEFAULT_CONTROLLERS, node='play_motion2'):
    """
    Return the play_motion2 parameters document of ``motions``.

    ``motions`` is an iterable of ``(name, joint_names, times, positions)`` with
    positions (keyframes, joints) in rad; ``descriptions`` maps names to a text;
    ``locks`` (joint -> rad) is named in every description.
    """
    descriptions = descriptions or {}
    note = ''
    if locks:
        note = ' [reconfigured: ' + ', '.join(
            f'{j} locked at {math.degrees(a):.2f} deg' for j, a in locks.items()) + ']'
    out = {}
    for name, joints, times, positions in motions:
        q = np.asarray(positions, dtype=float)
        if q.shape != (len(times), len(joints)):
            raise ValueError(f'{name}: {q.shape} positions for {len(times)} times and '
                             f'{len(joints)} joints')
        out[name] = {
            'joints': list(joints),
            'positions': [float(a) for a in q.ravel()],
            'times_from_start': [float(t) for t in times],
            'meta': {'name': name.replace('_', ' ').title(), 'usage': 'gesture',
                     'description': (descriptions.get(name, '') + note).strip()},
        }
    return {node: {'ros__parameters': {'controllers': list(controllers), 'motions': out}}}


def dump(document):
    """Return the document as YAML text (flow-style lists, one motion after another)."""
    return yaml.safe_dump(document, sort_keys=False, default_flow_style=None, width=99)


def load_motions(text, node='play_motion2'):
    """
    Parse a play_motion2 motions file; return ``{name: (joints, times, positions)}``.

    The node key may be written with or without its leading slash.
    """
    doc = yaml.safe_load(text)
    params = (doc.get(node) or doc.get('/' + node))['ros__parameters']
    out = {}
    for name, motion in params['motions'].items():
        joints = list(motion['joints'])
        times = [float(t) for t in motion['times_from_start']]
        flat = np.asarray(motion['positions'], dtype=float)
        if flat.size != len(joints) * len(times):
            raise ValueError(f'{name}: {flat.size} positions for {len(times)} times x '
                             f'{len(joints)} joints')
        out[name] = (joints, times, flat.reshape(len(times), len(joints)))
    return out
