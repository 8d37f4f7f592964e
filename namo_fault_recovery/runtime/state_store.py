"""
Persistence of the node's state: the fault set and the last published library.

Free of ROS.  The state is one JSON document, ``state.json`` in the state directory.  It
is written atomically (:func:`~namo_fault_recovery.files.write_text_atomically`: a
temporary file in the same directory, flushed and synced, then renamed over the old file
with ``os.replace``), so a reader (or a node restarted after SIGKILL or a power cut)
sees either the old state or the new one, never half of one.  A state file that cannot be
read back is *set aside* (renamed to ``state.json.corrupt-<time>``) and reported; it is
never fatal.
"""

from dataclasses import dataclass
import hashlib
import json
import os
from pathlib import Path
import threading
import time

from ..files import write_text_atomically
from ..recovery.result import finite_number, LibraryResult, MalformedResult

STATE_FILE = 'state.json'
FORMAT = 'namo_fault_recovery/state'
FORMAT_VERSION = 1


class StateFileError(MalformedResult):
    """The state file exists but its content is unusable."""


@dataclass(frozen=True)
class Fault:
    """
    One failed joint.

    ``angle`` is the lock angle (rad) given in the fault report, or None when the lock
    strategy chooses it.  ``measured`` is the joint's measured angle (rad) when the fault
    arrived, from ``/joint_states``, or None if none had been received.
    """

    angle: float = None
    measured: float = None

    def to_dict(self):
        """Return a JSON-ready dict."""
        return {'angle': self.angle, 'measured': self.measured}


@dataclass(frozen=True)
class PersistedState:
    """What survives a restart: the fault set, the last library and a config fingerprint."""

    faults: dict
    library: LibraryResult = None
    fingerprint: str = ''
    saved_at: float = 0.0


def fingerprint(*paths):
    """Return a hash of the content of the config files a library was computed from."""
    digest = hashlib.sha256()
    for path in paths:
        digest.update(str(path).encode() + b'\0')
        try:
            digest.update(Path(path).read_bytes())
        except OSError:
            digest.update(b'<unreadable>')
    return digest.hexdigest()


def encode_state(faults, library, fingerprint_=''):
    """Return the JSON text of a state (faults: joint -> Fault)."""
    doc = {
        'format': FORMAT, 'version': FORMAT_VERSION, 'saved_at': time.time(),
        'fingerprint': fingerprint_,
        'faults': {name: f.to_dict() for name, f in faults.items()},
        'library': library.to_dict() if library is not None else None,
    }
    return json.dumps(doc, indent=1, allow_nan=False) + '\n'


def decode_state(text):
    """Parse the JSON text of a state; raise StateFileError naming what is wrong."""
    try:
        doc = json.loads(text)
    except ValueError as exc:
        raise StateFileError(f'not valid JSON ({exc})') from None
    except RecursionError:
        raise StateFileError('not usable JSON (nested too deeply)') from None
    if not isinstance(doc, dict) or doc.get('format') != FORMAT:
        raise StateFileError(f"not a {FORMAT} document (missing or wrong 'format' key)")
    if doc.get('version') != FORMAT_VERSION:
        raise StateFileError(f"unsupported version {doc.get('version')!r}; "
                             f'expected {FORMAT_VERSION}')
    raw = doc.get('faults')
    if not isinstance(raw, dict):
        raise StateFileError(f"'faults': expected a mapping, got {raw!r}")
    faults = {}
    for name, entry in raw.items():
        if not isinstance(entry, dict):
            raise StateFileError(f'fault {name!r}: expected a mapping, got {entry!r}')
        angle, measured = entry.get('angle'), entry.get('measured')
        faults[str(name)] = Fault(
            None if angle is None else finite_number(angle, f'fault {name!r} angle'),
            None if measured is None else finite_number(measured, f'fault {name!r} measured'))
    library = doc.get('library')
    try:
        library = LibraryResult.from_dict(library) if library is not None else None
    except MalformedResult as exc:
        raise StateFileError(str(exc)) from None
    return PersistedState(faults, library, str(doc.get('fingerprint', '')),
                          float(doc.get('saved_at', 0.0) or 0.0))


class StateStore:
    """
    The state file in one directory, written atomically and read back defensively.

    Thread-safe: concurrent saves are serialised, and a save carrying an older sequence
    number than one already written is dropped, so the file never goes back in time.
    """

    def __init__(self, directory):
        self.directory = Path(os.path.expandvars(os.path.expanduser(str(directory))))
        self.path = self.directory / STATE_FILE
        self._lock = threading.Lock()
        self._written_seq = -1

    def load(self):
        """
        Read the state back.

        Return ``(state, problem)``: ``(None, None)`` when there is no file,
        ``(PersistedState, None)`` when it is good, and ``(None, message)`` when it was
        corrupted; the corrupted file has then been renamed aside and the message says
        where to.
        """
        try:
            text = self.path.read_text(encoding='utf-8')
        except FileNotFoundError:
            return None, None
        except (OSError, UnicodeDecodeError) as exc:
            return None, self.set_aside(f'cannot read it ({exc})')
        try:
            return decode_state(text), None
        except MalformedResult as exc:
            return None, self.set_aside(str(exc))

    def set_aside(self, reason):
        """Rename the state file aside; return a message naming the reason and new name."""
        stamp = time.strftime('%Y%m%dT%H%M%S')
        target = self.path.with_name(f'{STATE_FILE}.corrupt-{stamp}')
        n = 1
        while target.exists():
            target = self.path.with_name(f'{STATE_FILE}.corrupt-{stamp}-{n}')
            n += 1
        try:
            os.replace(self.path, target)
            where = f'set aside as {target}'
        except OSError as exc:
            where = f'and could not be set aside ({exc})'
        return f'state file {self.path} is corrupted: {reason}; {where}'

    def save(self, faults, library, fingerprint_='', seq=None):
        """
        Write the state atomically; return True if written.

        ``seq`` orders saves made from several threads: a save older than the last one
        written is skipped.  Raises OSError if the directory cannot be written.
        """
        text = encode_state(faults, library, fingerprint_)
        with self._lock:
            if seq is not None and seq < self._written_seq:
                return False
            write_text_atomically(self.path, text)
            if seq is not None:
                self._written_seq = seq
            return True


class BackgroundWriter:
    """
    Writes the newest snapshot of the state off the publishing path, in order.

    A library is written right after it is published (a crash in between loses only the
    library, never a fault: the fault set was written before it was acknowledged, and a
    restart recomputes a library whose fault set does not match).  Snapshots carry the
    sequence numbers of :meth:`StateStore.save`, so a slow write never overwrites a newer
    fault set; several pending snapshots collapse into the newest one.
    """

    def __init__(self, save):
        self._save = save                  # save(faults, library, seq)
        self._cond = threading.Condition()
        self._pending = None
        self._stopping = False
        self._busy = False
        self._thread = threading.Thread(target=self._loop, name='state-writer', daemon=True)

    def start(self):
        """Start the writer thread."""
        self._thread.start()

    def submit(self, faults, library, seq):
        """Queue a snapshot (replaces any older one not yet written)."""
        with self._cond:
            if self._pending is None or seq > self._pending[2]:
                self._pending = (dict(faults), library, seq)
            self._cond.notify_all()

    def flush(self, timeout=5.0):
        """Wait until every queued snapshot is written (e.g. before stopping)."""
        end = time.monotonic() + timeout
        with self._cond:
            while (self._pending is not None or self._busy) and self._thread.is_alive():
                remaining = end - time.monotonic()
                if remaining <= 0:
                    return False
                self._cond.wait(remaining)
        return True

    def _loop(self):
        while True:
            with self._cond:
                while self._pending is None and not self._stopping:
                    self._cond.wait()
                if self._pending is None:
                    return
                snapshot, self._pending = self._pending, None
                self._busy = True
            try:
                self._save(*snapshot)
            finally:
                with self._cond:
                    self._busy = False
                    self._cond.notify_all()

    def stop(self):
        """Write what is pending, then stop."""
        self.flush()
        with self._cond:
            self._stopping = True
            self._cond.notify_all()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
