"""
The contingency table: adapted libraries precomputed offline, one per likely fault set.

Free of ROS.  Within the 1 s deadline the engine finds a good library, not always the
best one it can find given minutes; and the fault sets worth preparing for are few (each
of the joints (14 on Namo) failing alone, then each further joint on top of the faults already in
force).  So ``namo-recovery precompute`` solves each of them without a deadline, with
several seeds, keeps the best library of each, and writes a table the node can look up
before (or instead of) a live run.

An entry is keyed by the *resolved* lock angles of its fault set (:func:`entry_key` of
:func:`table_locks`): joint names sorted, angles rounded to ``KEY_DECIMALS`` decimals of
a radian.  A lookup hits when the fault set at hand resolves to the same angles:

- ``average``: the lock is the library average, so every report of a joint without an
  angle hits (and so does a report giving exactly that angle);
- ``measured``: an entry is built at the average (there is no measured angle offline),
  so a live fault hits only if its measured angle equals the average; it usually misses,
  and the live run does the work, as without a table;
- ``optimal``: the entry is built with the lock left to the engine (it optimises it; the
  result's ``locks`` are the optimised angles), and is keyed by the average, which is
  what :func:`table_locks` resolves a joint without an angle to.

A table holds the :func:`table_fingerprint` of what it was built from: the robot model,
the gesture library, every :class:`~.engine.RecoverySettings` field but ``deadline_sec``
(the table is built without a deadline) and ``FORMAT_VERSION``.  A file whose
fingerprint differs, or that cannot be read back, is not used: :meth:`ContingencyTable.load`
returns an empty table and the reason, naming the file and the key at fault.  Changes
to the engine's code are not in the fingerprint: rebuild the table after an upgrade.

Usage::

    from namo_fault_recovery.recovery import contingency as ct
    fp = ct.table_fingerprint(robot, library, settings)
    table = ct.build_table(robot, library, settings,
                           ct.fault_sets(robot, library, settings), jobs=2)
    table.save(path)                                # atomically
    table, reason = ct.ContingencyTable.load(path, fp)   # reason: None, or why not used
    hit = table.lookup(ct.table_locks(robot, library, faults, settings, measured))
    if hit is not None:
        result = dataclasses.replace(hit, faults=faults)  # the request as the node has it

A stored result is the offline run's: ``deadline`` None, ``wall_time`` the offline time
of the best seed, ``seed`` that seed, ``faults`` the fault set it was built for.

File format (JSON, one document)::

    {"format": "namo_fault_recovery/contingency_table", "version": 1,
     "fingerprint": "<sha256 hex>", "info": {...free-form, for people...},
     "entries": [{"key": "right_arm_joint2=-0.248709", "locks": {joint: rad},
                  "result": <LibraryResult.to_dict()>}, ...]}
"""

from dataclasses import dataclass, fields, is_dataclass
import hashlib
import json
import math
import multiprocessing
import os
from pathlib import Path
import time

import numpy as np

from .engine import recover
from .locks import resolve_locks, validate_angle
from .motion import typical_points
from .result import LibraryResult, MalformedResult
from .settings import DEFAULT_STATE_DIR
from ..files import write_text_atomically
from ..optimize.base import Clock

FORMAT = 'namo_fault_recovery/contingency_table'
FORMAT_VERSION = 1
KEY_DECIMALS = 6              # lock angles in a key: rounded to 1e-6 rad
DEFAULT_SEEDS = (0, 1, 2, 3)
DEFAULT_BUDGET_SEC = None     # per seed; None: no deadline, the preset's full iterations
TABLE_FILE = 'contingency_table.json'
# The node's default state directory (the ``state_dir`` parameter) + TABLE_FILE.
DEFAULT_TABLE_PATH = f'{DEFAULT_STATE_DIR}/{TABLE_FILE}'
FLOAT_DIGITS = 12             # significant digits of a float in the fingerprint
NOT_CONTENT = ('source', 'warnings', 'tooled')   # dataclass fields a fingerprint skips


def canonical(value):
    """
    Return ``value`` as plain JSON data that is the same whenever the model is.

    Dataclasses become their fields (``source``, a file name, a library's load
    ``warnings`` and a profile arm's ``tooled`` cache left out: the content counts, not
    where it was read from, what was said about it or what was derived from it since),
    arrays and tuples lists, floats text with ``FLOAT_DIGITS`` significant digits (so
    that a round trip through a file or a harmless last-bit difference does not change a
    fingerprint); any other object its ``repr`` (a compiled chain's is its constants).
    """
    if is_dataclass(value) and not isinstance(value, type):
        return {f.name: canonical(getattr(value, f.name)) for f in fields(value)
                if f.name not in NOT_CONTENT}
    if isinstance(value, dict):
        return {str(k): canonical(v) for k, v in sorted(value.items(), key=lambda kv: str(kv[0]))}
    if isinstance(value, np.ndarray):
        return [canonical(v) for v in value.tolist()]
    if isinstance(value, (list, tuple)):
        return [canonical(v) for v in value]
    if value is None or isinstance(value, (bool, np.bool_, str)):
        return value if not isinstance(value, np.bool_) else bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return format(float(value) + 0.0, f'.{FLOAT_DIGITS}g')
    return repr(value)


def table_fingerprint(robot, library, settings):
    """
    Return the sha256 (hex) of everything that changes a table's libraries.

    The robot model (DH, limits, capsules, tools), the library (every gesture's name,
    arms, weights, joints, keyframe times and angles), every setting but
    ``deadline_sec``, the key rounding and ``FORMAT_VERSION``.
    """
    public = settings.public()
    public.pop('deadline_sec', None)
    doc = {'format': FORMAT, 'version': FORMAT_VERSION, 'key_decimals': KEY_DECIMALS,
           'robot': canonical(robot), 'library': canonical(library),
           'settings': canonical(public)}
    text = json.dumps(doc, sort_keys=True, separators=(',', ':'), allow_nan=True)
    return hashlib.sha256(text.encode('utf-8')).hexdigest()


def table_locks(robot, library, faults, settings, measured=None):
    """
    Return the lock angles (joint -> rad) a fault set resolves to: what keys an entry.

    :func:`~.locks.resolve_locks` with the settings' strategy (``measured`` maps joints
    to measured angles, for the ``measured`` strategy).  Raises ValueError for an
    unknown joint or an angle beyond the limits.
    """
    locks, _ = resolve_locks(robot, library, faults, settings.lock_strategy, measured)
    return locks


def entry_key(locks):
    """
    Return the canonical key of lock angles ``{joint: rad}``.

    ``joint=angle`` pairs sorted by joint and joined by ``;``, each angle with
    ``KEY_DECIMALS`` decimals (so an angle read back from a file, or computed again
    with a last-bit difference, gives the same key).  ``''`` for no locks.
    """
    parts = []
    for joint in sorted(locks):
        angle = float(locks[joint])
        if not math.isfinite(angle):
            raise ValueError(f'lock angle of {joint}: expected a finite angle, got {angle!r}')
        parts.append(f'{joint}={round(angle, KEY_DECIMALS) + 0.0:.{KEY_DECIMALS}f}')
    return ';'.join(parts)


def fault_sets(robot, library, settings, active=None, joints=None):
    """
    Return the fault sets to precompute: each joint failing on top of ``active``.

    ``active`` maps joints already failed to their lock angles (rad, or None for the
    strategy's); ``joints`` limits the new failures to these (default: all the robot's joints,
    right arm first).  Joints of ``active`` are not failed again.  With the ``average``
    and ``measured`` strategies every angle is resolved (:func:`table_locks`; measured
    falls back to the average offline); with ``optimal`` the joints without an angle stay
    None, so that the engine optimises their locks as it does live.  Raises ValueError
    for an unknown joint or an active angle beyond its limits.
    """
    active = dict(active or {})
    for joint, angle in active.items():
        validate_angle(robot, joint, angle)
    names = robot.joint_names if joints is None else tuple(joints)
    for joint in names:
        validate_angle(robot, joint, None)
    out = []
    for joint in names:
        if joint in active:
            continue
        faults = dict(active)
        faults[joint] = None
        if settings.lock_strategy != 'optimal':
            faults = table_locks(robot, library, faults, settings)
        out.append(faults)
    return out


@dataclass(frozen=True)
class BuiltEntry:
    """
    One entry as built: the best result and how the seeds compared.

    ``locks`` are the key's lock angles (:func:`table_locks`; for ``optimal`` not the
    result's own); ``seed_scores`` the ``total_score`` of every seed's library, in seed
    order; ``cpu_sec`` and ``wall_sec`` the process CPU and wall seconds of all seeds
    together.  The fault set is the result's (``faults``).
    """

    locks: dict
    result: LibraryResult
    seed_scores: tuple
    cpu_sec: float
    wall_sec: float

    @property
    def faults(self) -> dict:
        """Return the fault set the entry was built for (the result's)."""
        return self.result.faults

    @property
    def key(self) -> str:
        """Return the entry's key."""
        return entry_key(self.locks)


def build_entry(robot, library, faults, settings, seeds=DEFAULT_SEEDS,
                budget_sec=DEFAULT_BUDGET_SEC, quantisations=None):
    """
    Return the best :class:`LibraryResult` for ``faults`` over several seeds.

    Each seed is one :func:`~.engine.recover` run with ``Clock(budget_sec)`` (None, the
    default: no deadline, the optimiser preset's full iterations, about 1 s of CPU per
    seed for a Namo joint).  Best = lowest ``total_score``; a tie goes to the first seed.
    """
    return measure_entry(robot, library, faults, settings, seeds, budget_sec,
                         quantisations).result


def measure_entry(robot, library, faults, settings, seeds=DEFAULT_SEEDS,
                  budget_sec=DEFAULT_BUDGET_SEC, quantisations=None):
    """Build one entry as :func:`build_entry` does; return the :class:`BuiltEntry`."""
    seeds = tuple(int(s) for s in seeds)
    if not seeds:
        raise ValueError('seeds: expected at least one seed')
    locks = table_locks(robot, library, faults, settings)
    cpu, wall = time.process_time(), time.monotonic()
    if quantisations is None:
        quantisations = typical_points(robot, library, settings.vq_distortion_mm)
    best, scores = None, []
    for seed in seeds:
        result = recover(robot, library, faults, settings, seed=seed,
                         clock=Clock(budget_sec), quantisations=quantisations)
        scores.append(result.total_score)
        if best is None or result.total_score < best.total_score:
            best = result
    return BuiltEntry(locks, best, tuple(scores),
                      time.process_time() - cpu, time.monotonic() - wall)


class TableFileError(MalformedResult):
    """A table file that cannot be used (the message names the file and the key)."""


class ContingencyTable:
    """
    Precomputed libraries keyed by resolved lock angles, for one fingerprint.

    ``entries`` maps :func:`entry_key` to ``(locks, LibraryResult)``; ``info`` is
    free-form data for people (how the table was built), saved with it.
    """

    def __init__(self, fingerprint, entries=None, info=None):
        self.fingerprint = str(fingerprint)
        self.entries = dict(entries or {})
        self.info = dict(info or {})

    def __len__(self):
        return len(self.entries)

    def __contains__(self, locks):
        return entry_key(locks) in self.entries

    def lookup(self, locks):
        """Return the library stored for these lock angles ``{joint: rad}``, or None."""
        entry = self.entries.get(entry_key(locks))
        return None if entry is None else entry[1]

    def add(self, result, locks=None):
        """
        Store ``result`` under ``locks`` (default: ``result.locks``); return the key.

        Pass the fault set's :func:`table_locks` for an ``optimal`` result, whose own
        ``locks`` are the optimised angles, not the ones a lookup resolves to.
        """
        locks = {str(j): float(a) for j, a in dict(result.locks if locks is None
                                                   else locks).items()}
        key = entry_key(locks)
        self.entries[key] = (locks, result)
        return key

    def to_dict(self):
        """Return the JSON-ready document of the table (entries sorted by key)."""
        return {'format': FORMAT, 'version': FORMAT_VERSION, 'fingerprint': self.fingerprint,
                'info': self.info,
                'entries': [{'key': key, 'locks': dict(locks), 'result': result.to_dict()}
                            for key, (locks, result) in sorted(self.entries.items())]}

    @classmethod
    def from_dict(cls, doc):
        """Rebuild a table from :meth:`to_dict` output; raise TableFileError naming the key."""
        if not isinstance(doc, dict) or doc.get('format') != FORMAT:
            raise TableFileError(f"'format': not a {FORMAT} document")
        if doc.get('version') != FORMAT_VERSION:
            raise TableFileError(f"'version': unsupported version {doc.get('version')!r}; "
                                 f'expected {FORMAT_VERSION}')
        if not isinstance(doc.get('fingerprint'), str):
            raise TableFileError("'fingerprint': expected a string")
        info = doc.get('info', {})
        if not isinstance(info, dict):
            raise TableFileError("'info': expected a mapping")
        raw = doc.get('entries')
        if not isinstance(raw, list):
            raise TableFileError("'entries': expected a list")
        table = cls(doc['fingerprint'], info=info)
        for i, entry in enumerate(raw):
            where = f"'entries'[{i}]"
            try:
                if not isinstance(entry, dict) or not isinstance(entry.get('locks'), dict):
                    raise MalformedResult("expected a mapping with 'key', 'locks', 'result'")
                locks = {str(j): float(a) for j, a in entry['locks'].items()}
                key = entry_key(locks)
                if entry.get('key') != key:
                    raise MalformedResult(f"'key' {str(entry.get('key'))[:100]!r} does not "
                                          f"match its 'locks' ({key!r})")
                result = LibraryResult.from_dict(entry.get('result'))
            except (MalformedResult, TypeError, ValueError, AttributeError) as exc:
                raise TableFileError(f'{where}: {exc}') from None
            table.entries[key] = (locks, result)
        return table

    def save(self, path):
        """Write the table to ``path`` atomically (tmp file, fsync, rename); OSError if not."""
        text = json.dumps(self.to_dict(), indent=1, allow_nan=True) + '\n'
        write_text_atomically(expand(path), text, private=False)

    @classmethod
    def load(cls, path, fingerprint):
        """
        Read a table; return ``(table, reason)``.

        ``reason`` is None when the file was read and matches ``fingerprint``.  Otherwise
        the table is empty (with ``fingerprint``) and ``reason`` is one line naming the
        file and what is wrong with it (missing, unreadable, corrupt or truncated at a
        named key, built for another robot, library or settings): the node logs it and
        runs live.
        """
        path = expand(path)
        empty = cls(fingerprint)
        try:
            text = path.read_text(encoding='utf-8')
        except FileNotFoundError:
            return empty, f'contingency table {path}: no such file'
        except (OSError, UnicodeDecodeError) as exc:
            return empty, f'contingency table {path}: cannot read it ({exc})'
        try:
            doc = json.loads(text)
        except ValueError as exc:
            return empty, f'contingency table {path}: not valid JSON, truncated? ({exc})'
        except RecursionError:
            return empty, f'contingency table {path}: not usable JSON (nested too deeply)'
        try:
            table = cls.from_dict(doc)
        except TableFileError as exc:
            return empty, f'contingency table {path}: {exc}'
        if table.fingerprint != fingerprint:
            return empty, (f"contingency table {path}: 'fingerprint' {table.fingerprint[:12]} "
                           f'is not {fingerprint[:12]}, that of the robot, library and '
                           f'settings in use; not used (rebuild it with namo-recovery '
                           f'precompute)')
        return table, None


def expand(path):
    """Return ``path`` with ``~`` and environment variables expanded."""
    return Path(os.path.expandvars(os.path.expanduser(str(path))))


WORKER = {}                   # the pool worker's models, set by init_worker


def init_worker(robot, library, settings, seeds, budget_sec):
    """Initialise a pool worker (spawned): keep the models and the build options."""
    WORKER.update(robot=robot, library=library, settings=settings, seeds=seeds,
                  budget_sec=budget_sec,
                  quantisations=typical_points(robot, library, settings.vq_distortion_mm))


def build_in_worker(faults):
    """Build one entry in a pool worker; return the :class:`BuiltEntry`."""
    w = WORKER
    return measure_entry(w['robot'], w['library'], faults, w['settings'], w['seeds'],
                         w['budget_sec'], w['quantisations'])


def build_table(robot, library, settings, fault_sets, jobs=1, progress=None,
                seeds=DEFAULT_SEEDS, budget_sec=DEFAULT_BUDGET_SEC):
    """
    Build a :class:`ContingencyTable` with one entry per fault set.

    ``jobs`` > 1 shares the entries out over a ``multiprocessing`` pool (``spawn``
    context: nothing of the caller's threads is forked; the models are pickled to each
    worker once).  ``progress(built)`` is called with each :class:`BuiltEntry`, in the
    order of ``fault_sets``.  Entries do not depend on ``jobs``: with ``budget_sec``
    None each is a function of its seeds.
    """
    seeds = tuple(int(s) for s in seeds)
    fault_sets = [dict(f) for f in fault_sets]
    table = ContingencyTable(table_fingerprint(robot, library, settings),
                             info={'robot': str(robot.source), 'library': str(library.source),
                                   'seeds': list(seeds), 'budget_sec': budget_sec,
                                   'built_at': time.time()})
    jobs = max(1, min(int(jobs), len(fault_sets) or 1))

    def keep(built):
        table.add(built.result, built.locks)
        if progress is not None:
            progress(built)
    if jobs == 1:
        init_worker(robot, library, settings, seeds, budget_sec)
        try:
            for faults in fault_sets:
                keep(build_in_worker(faults))
        finally:
            WORKER.clear()
        return table
    context = multiprocessing.get_context('spawn')
    with context.Pool(jobs, initializer=init_worker,
                      initargs=(robot, library, settings, seeds, budget_sec)) as pool:
        for built in pool.imap(build_in_worker, fault_sets):
            keep(built)
    return table
