"""
``bench robots``: every single fault x the four gestures on a robot from its profile.

For a shipped robot (``--robot NAME``: ``config/robots/<name>.yaml`` and its retargeted
library ``<name>_gestures.yaml``) or any other (``--profile FILE --gesture-file FILE``,
a :class:`BenchRobot`), two parts, the way :mod:`.product` measures Namo:

- optima (``--update-optima``): the best-known ``score_after`` per single fault and
  gesture, the lowest over ``--optima-seeds`` seeds of :func:`recover` without a
  deadline (the node's settings and preset; only seeds whose keyframes respect the
  velocity limits), stored with the model fingerprint in ``<profile>_best_known.yaml``
  beside the profile (``config/robots/<name>_best_known.yaml``) or in ``--optima``;
- quality: every single fault x ``--seeds`` seeds through :func:`recover` at the node's
  1 s deadline with the cached typical points, as the node's engine runs a table miss;
  each run's wall time (the table miss's solve, without the node's transport) and each
  gesture's gap to the best-known (target: every gesture within 1 % in >= 99 % of the
  runs).  Wall times depend on load: run it under the shared lock.
"""

from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
import time

import numpy as np
import yaml

from . import common
from .product import gap, git_commit, playable, QUALITY_TARGET, QUALITY_WITHIN
from ..model.gestures import load_library
from ..model.profile_robot import robot_from_profile
from ..optimize.base import Clock
from ..recovery.contingency import entry_key, fault_sets
from ..recovery.engine import recover, RecoverySettings
from ..recovery.motion import typical_points
from ..resources import config_path, share_dir

ROBOTS = ('talos', 'tiago_dual')
QUALITY_SEED_BASE = 1000
SLOWEST_SHOWN = 3          # faults named by their median solve time


@dataclass(frozen=True)
class BenchRobot:
    """A robot of ``bench robots``: its profile, its gesture library and its optima file."""

    name: str
    profile: Path
    gestures: Path
    optima: Path
    command: str            # the command line's robot arguments, for ``generated_by``

    def models(self):
        """Return ``(robot, library)``: the profile's robot and its library."""
        robot = robot_from_profile(self.profile)
        return robot, load_library(robot, self.gestures)


def shipped_robot(name, optima=None) -> BenchRobot:
    """Return a shipped robot (``config/robots/<name>.yaml``) of ``bench robots``."""
    if name not in ROBOTS:
        raise ValueError(f'--robot: expected one of {", ".join(ROBOTS)}, got {name!r}')
    return BenchRobot(name, config_path(f'robots/{name}.yaml'),
                      config_path(f'robots/{name}_gestures.yaml'),
                      Path(optima) if optima else optima_path(name), f'--robot {name}')


def profile_robot(profile, gestures, optima=None) -> BenchRobot:
    """
    Return any robot of ``bench robots``: a recovery profile and its gesture library.

    Its best-known optima are ``optima``, or ``<profile stem>_best_known.yaml`` beside
    the profile (where a shipped robot's are).
    """
    profile, gestures = Path(profile), Path(gestures)
    optima = Path(optima) if optima else profile.with_name(f'{profile.stem}_best_known.yaml')
    return BenchRobot(profile.stem, profile, gestures, optima,
                      f'--profile {profile} --gesture-file {gestures}')


def robot_models(name):
    """Return ``(robot, library)`` of a shipped robot profile and its retargeted library."""
    return shipped_robot(name).models()


def optima_path(name):
    """Return the path of a shipped robot's best-known optima file."""
    return share_dir('config') / 'robots' / f'{name}_best_known.yaml'


def _single_faults(robot, library, settings, joints=None):
    sets = fault_sets(robot, library, settings, joints=joints)
    return {entry_key(f): dict.fromkeys(f) for f in sets}


def generate_optima(out, bench: BenchRobot, seeds=16, joints=None):
    """Return the best-known document of ``bench``'s robot (min over ``seeds`` per gesture)."""
    settings = RecoverySettings()
    name = bench.name
    robot, lib = bench.models()
    quant = typical_points(robot, lib, settings.vq_distortion_mm)
    began = time.monotonic()
    cases = {}
    faults_of = _single_faults(robot, lib, settings, joints)
    prog = common.Progress(len(faults_of) * seeds, f'optima {name}')
    for key, faults in faults_of.items():
        best = {}
        for seed in range(seeds):
            res = recover(robot, lib, faults, settings, seed=seed, clock=Clock(None),
                          quantisations=quant)
            for g in res.gestures:
                ok = playable(robot, g)
                cand = (not ok, float(g.score_after))
                best[g.name] = min(best.get(g.name, cand), cand)
            prog.step()
        cases[key] = {g: v[1] for g, v in best.items()}
    wall = time.monotonic() - began
    out.write(f'optima {name}: {len(faults_of) * seeds} runs in {wall:.0f} s\n')
    return {'version': 1, 'robot': name, 'seeds': seeds,
            'method': 'per single fault, recover() without a deadline, seeds 0..N-1, the '
                      'node settings; per gesture the lowest score_after over the seeds '
                      'whose keyframes respect the velocity limits',
            'generated_by': f'namo-recovery bench robots {bench.command} --update-optima '
                            f'--optima-seeds {seeds}',
            'made': {'date': datetime.now(timezone.utc).strftime('%Y-%m-%dT%H:%M:%SZ'),
                     'commit': git_commit(), 'wall_sec': round(wall, 1)},
            'model_fingerprint': common.model_fingerprint(robot, lib),
            'fault_sets': cases}


def keep_lower(doc, previous):
    """
    Return ``doc`` with every value that ``previous`` knew lower kept from it.

    A best-known optimum is the lowest score ever found for that model: a search change
    that stops finding a basin (Talos's Wai with right joint 3: 37.96 over 24 seeds on
    2026-12-04, 38.85 over the same seeds since 2026-12-06) must not raise the bar it is
    measured against.  Kept only while ``previous`` is of the same model (its
    ``model_fingerprint``), as are the fault sets this run did not solve (``--joints``);
    ``doc['kept']`` counts the values kept.
    """
    if not previous or previous.get('model_fingerprint') != doc['model_fingerprint']:
        return doc
    earlier = previous.get('fault_sets', {})
    kept = sum(len(common.keep_lower_scores(scores, earlier.get(key, {})))
               for key, scores in doc['fault_sets'].items())
    for key, scores in earlier.items():                          # not run this time
        doc['fault_sets'].setdefault(key, {name: float(v) for name, v in scores.items()})
    doc['kept'] = kept
    doc['method'] += ('; a value found lower by an earlier run for the same model is kept '
                      f'({kept} here)')
    return doc


def load_optima(bench: BenchRobot):
    """Return a robot's stored best-known document, or raise FileNotFoundError."""
    with open(bench.optima, encoding='utf-8') as handle:
        return yaml.safe_load(handle)


def optima_warning(bench: BenchRobot, best_doc, robot, lib) -> str:
    """Return a line if ``best_doc`` was made for another model than ``robot``, else ''."""
    if best_doc.get('model_fingerprint') != common.model_fingerprint(robot, lib):
        return f'warning: {bench.optima} was made for another model; rerun with --update-optima'
    return ''


def run_quality(out, bench: BenchRobot, best_doc, seeds=10, joints=None, deadline=None,
                expand_shared=False):
    """
    Run every single fault x ``seeds`` at the deadline; print and return the summary.

    ``expand_shared`` turns the torso's lean on (the setting of that name).
    """
    settings = RecoverySettings(expand_shared=bool(expand_shared))
    if deadline is not None:
        settings = settings.with_changes(deadline_sec=float(deadline))
    robot, lib = bench.models()
    warning = optima_warning(bench, best_doc, robot, lib)
    if warning:
        out.write(warning + '\n')
    quant = typical_points(robot, lib, settings.vq_distortion_mm)
    faults_of = _single_faults(robot, lib, settings, joints)
    recover(robot, lib, next(iter(faults_of.values())), settings, seed=0,
            quantisations=quant)                        # warm-up, as the engine child
    runs = []
    for key, faults in faults_of.items():
        best = best_doc['fault_sets'][key]
        for seed in range(QUALITY_SEED_BASE, QUALITY_SEED_BASE + seeds):
            t0 = time.monotonic()
            res = recover(robot, lib, faults, settings, seed=seed, quantisations=quant)
            wall = time.monotonic() - t0
            gaps = {g.name: gap(g.score_after, best[g.name]) for g in res.gestures}
            runs.append({'fault': key, 'wall_s': wall, 'met': res.deadline_met,
                         'gaps': gaps, 'collides': any(g.collides for g in res.gestures),
                         'leaned': sorted(g.name for g in res.gestures if g.shared)})
    summary = _summary(bench.name, runs, lib.names, settings.deadline_sec, seeds)
    summary['faults'] = 'every single fault' if joints is None else \
        f'the single faults of {", ".join(joints)}'
    _print(out, summary)
    return summary


def _summary(name, runs, names, deadline, seeds):
    within = [max(r['gaps'].values()) <= QUALITY_WITHIN for r in runs]
    misses, walls = {}, {}
    for r, ok in zip(runs, within):
        joint = r['fault'].split('=')[0]
        walls.setdefault(joint, []).append(r['wall_s'])
        if not ok:
            misses[joint] = misses.get(joint, 0) + 1
    # A fault's solve time barely moves from seed to seed, so the p95 of the runs is
    # about the second-slowest fault's: these say where to look.
    slowest = sorted(((1000 * common.percentile(w, 50), j) for j, w in walls.items()),
                     reverse=True)[:SLOWEST_SHOWN]
    return {'robot': name, 'runs': len(runs), 'seeds': seeds, 'deadline_sec': deadline,
            'share_within': float(np.mean(within)),
            'met': float(np.mean(within)) >= QUALITY_TARGET,
            'wall_p50_ms': 1000 * common.percentile([r['wall_s'] for r in runs], 50),
            'wall_p95_ms': 1000 * common.percentile([r['wall_s'] for r in runs], 95),
            'wall_max_ms': 1000 * max(r['wall_s'] for r in runs),
            'deadline_met_share': float(np.mean([r['met'] for r in runs])),
            'colliding_runs': sum(r['collides'] for r in runs),
            'leaned': _leaned(runs),
            'max_gap_pct': {g: 100 * max(r['gaps'][g] for r in runs) for g in names},
            'misses_by_fault': misses,
            'slowest_faults_median_ms': {j: ms for ms, j in slowest}}


def _leaned(runs):
    """Return {fault joint: {gesture: runs in which the torso leaned}}."""
    out = {}
    for r in runs:
        for name in r['leaned']:
            per = out.setdefault(r['fault'].split('=')[0], {})
            per[name] = per.get(name, 0) + 1
    return out


def _print(out, s):
    out.write(f"\n== {s['robot']}: {s.get('faults', 'every single fault')} x {s['seeds']} "
              f"seeds at the {s['deadline_sec']:g} s deadline ==\n")
    out.write(common.text_table(
        ['runs', 'solve p50 ms', 'solve p95 ms', 'max ms', 'deadline met',
         'all within 1%', 'target', 'verdict', 'colliding runs'],
        [[s['runs'], common.fmt(s['wall_p50_ms'], 1), common.fmt(s['wall_p95_ms'], 1),
          common.fmt(s['wall_max_ms'], 1), f"{100 * s['deadline_met_share']:.0f}%",
          f"{100 * s['share_within']:.1f}%", f'{100 * QUALITY_TARGET:.0f}%',
          'met' if s['met'] else 'MISSED', s['colliding_runs']]]))
    out.write('  worst gap per gesture: ' + ', '.join(
        f'{g} {v:.2f}%' for g, v in s['max_gap_pct'].items()) + '\n')
    if s['misses_by_fault']:
        out.write('  runs beyond 1% by fault: ' + ', '.join(
            f'{k}: {n}' for k, n in sorted(s['misses_by_fault'].items())) + '\n')
    if s['leaned']:
        out.write('  the torso leaned (expand_shared): ' + ', '.join(
            f'{j} {g} {n}x' for j, per in sorted(s['leaned'].items())
            for g, n in sorted(per.items())) + '\n')
    out.write('  slowest faults (median solve ms): ' + ', '.join(
        f'{k} {ms:.1f}' for k, ms in s['slowest_faults_median_ms'].items()) + '\n')
