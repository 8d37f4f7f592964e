"""The state file: atomic writes, exact round trips, corrupted files set aside."""

import json
import os
import threading

from namo_fault_recovery.recovery.result import GestureResult, LibraryResult
from namo_fault_recovery.runtime import state_store
from namo_fault_recovery.runtime.state_store import (decode_state, encode_state, Fault,
                                                     StateFileError, StateStore)
import pytest


def library(angle=0.1):
    gestures = (
        GestureResult('wai', (2.0,), ((angle, -0.2487094184091919, 0.1 + 0.2) + (0.0,) * 11,),
                      score_before=61.96, score_after=25.5, wall_time=0.2, status='converged',
                      message='wai: reconfigured', breakdown={'elbow': 1.5}),
        GestureResult('bye', (1.0, 2.5), ((0.0,) * 14, (1e-300,) * 14)),
    )
    return LibraryResult(gestures, faults={'right_arm_joint2': None},
                         locks={'right_arm_joint2': -0.2487094184091919},
                         frozen_arms=('left',), wall_time=0.21, deadline=1.0,
                         settings={'lock_strategy': 'average', 'seed': 7})


FAULTS = {'right_arm_joint2': Fault(None, 0.25), 'left_arm_joint4': Fault(0.3, None)}


def test_round_trip_is_exact():
    state = decode_state(encode_state(FAULTS, library(), 'abc'))
    assert state.faults == FAULTS
    assert list(state.faults) == list(FAULTS)            # arrival order kept
    assert state.library == library()
    assert state.library.gestures[0].positions[0][2] == 0.1 + 0.2   # floats bit for bit
    assert state.fingerprint == 'abc'


def test_save_then_load(tmp_path):
    store = StateStore(tmp_path / 'deep' / 'dir')
    assert store.load() == (None, None)
    assert store.save(FAULTS, library())
    state, problem = store.load()
    assert problem is None and state.faults == FAULTS and state.library == library()
    assert store.save({}, None)
    state, _ = store.load()
    assert state.faults == {} and state.library is None
    assert os.listdir(store.directory) == ['state.json']    # no temporary file left


def test_directory_expands_home_and_variables(monkeypatch, tmp_path):
    monkeypatch.setenv('HOME', str(tmp_path))
    monkeypatch.setenv('NAMO_SUB', 'robot1')
    store = StateStore('~/.ros/$NAMO_SUB')
    assert store.directory == tmp_path / '.ros' / 'robot1'


def test_a_failed_write_leaves_the_old_state_intact(tmp_path, monkeypatch):
    store = StateStore(tmp_path)
    store.save(FAULTS, library())
    before = store.path.read_text()

    def broken_replace(src, dst):
        raise OSError('disk full')
    monkeypatch.setattr(state_store.os, 'replace', broken_replace)
    with pytest.raises(OSError, match='disk full'):
        store.save({}, None)
    assert store.path.read_text() == before
    assert os.listdir(tmp_path) == ['state.json']


def test_older_saves_never_overwrite_newer_ones(tmp_path):
    store = StateStore(tmp_path)
    assert store.save({'a': Fault(0.5)}, None, seq=5)
    assert not store.save({'b': Fault(0.1)}, None, seq=3)
    assert list(store.load()[0].faults) == ['a']


def test_concurrent_saves_end_on_the_newest(tmp_path):
    store = StateStore(tmp_path)
    threads = [threading.Thread(target=store.save, args=({f'j{i}': Fault(i * 0.01)}, None),
                                kwargs={'seq': i}) for i in range(40)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert list(store.load()[0].faults) == ['j39']
    assert os.listdir(tmp_path) == ['state.json']


@pytest.mark.parametrize('content, reason', [
    ('{"format": "namo_fault_recovery/state", ', 'not valid JSON'),
    ('', 'not valid JSON'),
    ('"hello"', "missing or wrong 'format' key"),
    (json.dumps({'format': 'namo_fault_recovery/state', 'version': 99, 'faults': {}}),
     'unsupported version 99'),
    (json.dumps({'format': 'namo_fault_recovery/state', 'version': 1, 'faults': []}),
     "'faults': expected a mapping"),
    ('{"format": "namo_fault_recovery/state", "version": 1, '
     '"faults": {"right_arm_joint1": {"angle": NaN}}}', 'expected a finite number'),
    (json.dumps({'format': 'namo_fault_recovery/state', 'version': 1,
                 'faults': {'right_arm_joint1': {'angle': 'x'}}}), 'expected a number'),
    (json.dumps({'format': 'namo_fault_recovery/state', 'version': 1, 'faults': {},
                 'library': {'gestures': [{'name': 'wai', 'times': [1.0],
                                           'positions': []}], 'locks': {}}}),
     '1 times for 0 keyframes'),
])
def test_corrupted_file_is_reported_and_set_aside(tmp_path, content, reason):
    store = StateStore(tmp_path)
    store.path.write_text(content)
    state, problem = store.load()
    assert state is None
    assert 'corrupted' in problem and reason in problem and 'set aside as' in problem
    aside = list(tmp_path.glob('state.json.corrupt-*'))
    assert len(aside) == 1 and aside[0].read_text() == content
    assert not store.path.exists()
    assert store.load() == (None, None)       # the next start is clean


def test_set_aside_names_never_collide(tmp_path):
    store = StateStore(tmp_path)
    for _ in range(3):
        store.path.write_text('garbage')
        assert store.load()[0] is None
    assert len(list(tmp_path.glob('state.json.corrupt-*'))) == 3


def test_decode_rejects_non_finite_library_angles():
    doc = json.loads(encode_state({}, library()))
    doc['library']['gestures'][0]['positions'][0][0] = 1e400   # parses as inf
    with pytest.raises(StateFileError, match='finite'):
        decode_state(json.dumps(doc))


def test_unwritable_directory_raises_oserror(tmp_path):
    blocker = tmp_path / 'file'
    blocker.write_text('')
    with pytest.raises(OSError):
        StateStore(blocker / 'state').save({}, None)


# --- the fault journal: the durable step of a fault, before the state file follows ---------

def test_a_journal_record_newer_than_the_state_file_wins(tmp_path):
    store = StateStore(tmp_path)
    assert store.save(FAULTS, library(), 'fp', seq=3)
    store.journal.append(2, {})                       # older than the file: ignored
    assert store.load()[0].faults == FAULTS
    newer = {'left_arm_joint1': Fault(0.5, None)}
    store.journal.append(4, newer)
    state, problem = store.load()
    assert problem is None and state.faults == newer and state.seq == 4
    assert state.library == library() and state.fingerprint == 'fp'   # kept: recomputed
    assert store.newest_seq() == 4
    store.journal.close()


def test_a_torn_last_record_is_ignored(tmp_path):
    store = StateStore(tmp_path)
    store.journal.append(1, FAULTS)
    store.journal.close()
    line = state_store.encode_record(2, {'right_arm_joint5': Fault(0.1)})
    with open(store.journal.path, 'ab') as f:
        f.write(line[:len(line) // 2])                # the process died mid-append
    state, problem = store.load()
    assert problem is None and state.faults == FAULTS and state.library is None
    flipped = bytearray(line)
    flipped[-5] ^= 1                                  # a changed byte fails the checksum
    assert state_store.decode_record(bytes(flipped).rstrip(b'\n')) is None


def test_saving_a_newer_state_empties_the_journal_but_never_a_newer_record(tmp_path):
    store = StateStore(tmp_path)
    store.journal.append(5, FAULTS)
    assert store.save({}, None, seq=4)                # older than the record: kept
    assert store.load()[0].faults == FAULTS
    assert store.save(FAULTS, None, seq=6)
    assert store.journal.path.read_bytes() == b''
    assert store.load()[0].faults == FAULTS and store.load()[0].seq == 6
    store.journal.close()


def test_a_corrupted_state_file_is_set_aside_and_the_journal_still_counts(tmp_path):
    store = StateStore(tmp_path)
    store.path.write_text('{')
    store.journal.append(1, FAULTS)
    state, problem = store.load()
    assert 'set aside' in problem and state.faults == FAULTS and state.library is None
    store.journal.close()


def test_a_write_between_the_reads_never_hides_the_newest_fault_set(tmp_path, monkeypatch):
    # A running node writes while a reader loads: the state file (the cleared fault set,
    # change 6) replaces the old one (change 3), then the journal holding change 5 is emptied.
    store = StateStore(tmp_path)
    assert store.save(FAULTS, library(), 'fp', seq=3)
    store.journal.append(5, {})
    records = store.journal.records

    def writer_catches_up():
        assert store.save({}, library(), 'fp', seq=6)     # replaces the file, empties
        return records()

    monkeypatch.setattr(store.journal, 'records', writer_catches_up)
    state, problem = store.load()
    assert problem is None and state.faults == {}
    store.journal.close()


def test_a_record_written_and_not_yet_synced_is_never_emptied_away(tmp_path):
    """The state file catching up meanwhile must not truncate a record on its way to disk."""
    store = StateStore(tmp_path)
    store.journal.write(7, FAULTS)
    store.journal.empty_if_covered(5)          # the state file holds change 5 only
    store.journal.sync()
    assert store.journal.records() == [(7, FAULTS)]
    store.journal.empty_if_covered(7)
    assert store.journal.records() == []
