"""Fast unit tests of the anytime refinement and of the run book's refined versions."""

from dataclasses import replace
import json
import multiprocessing
import os
import time

from namo_fault_recovery.optimize.base import Clock
from namo_fault_recovery.recovery.engine import recover, RecoverySettings
from namo_fault_recovery.recovery.refine import refinement_faults, refinements
from namo_fault_recovery.runtime.contingency_keeper import ContingencyKeeper, TABLE_FILE
from namo_fault_recovery.runtime.engine_process import die_with_parent
from namo_fault_recovery.runtime.run_book import RunBook
from namo_fault_recovery.runtime.state_store import Fault

SETTINGS = RecoverySettings(deadline_sec=0.02)
FAULT = {'right_arm_joint1': None}


def test_each_refinement_is_better_and_keeps_the_locks(robot, product_library):
    published = recover(robot, product_library, FAULT, SETTINGS, seed=0)
    assert published.origin == 'deadline'
    totals = [published.total_score]
    for better in refinements(robot, product_library, published, SETTINGS,
                              clock=Clock(20.0), seeds=range(1, 4)):
        assert better.origin == 'refined' and better.locks == published.locks
        # The deadline is the published result's; the refinement's time is apart.
        assert better.deadline == published.deadline
        assert better.deadline_met == published.deadline_met
        assert 0.0 < better.refined_after < 20.0
        assert better.faults == published.faults
        assert better.total_score < totals[-1] * (1 - 1e-3)
        totals.append(better.total_score)
    assert len(totals) > 1, 'a 20 ms search was not improved by three full runs'


def test_a_cancel_ends_the_refinement_at_once(robot, product_library):
    published = recover(robot, product_library, FAULT, SETTINGS, seed=0)
    clock = Clock(60.0, cancel=lambda: True)
    assert list(refinements(robot, product_library, published, SETTINGS, clock=clock)) == []


def test_the_optimal_strategy_searches_the_lock_again(robot, product_library):
    published = recover(robot, product_library, FAULT, SETTINGS, seed=0)
    assert refinement_faults(published, SETTINGS) == published.locks
    optimal = SETTINGS.with_changes(lock_strategy='optimal')
    assert refinement_faults(published, optimal) == published.faults


def test_a_refined_version_only_for_the_current_published_generation():
    book = RunBook()
    book.set_faults({'right_arm_joint1': Fault()})
    run = book.next_run(timeout=1.0)
    assert not book.refining(run.generation)           # not published yet
    book.publish(run.generation, 'first', lambda r: 10)
    assert book.refining(run.generation) == 1          # the version it refines
    assert book.publish_refined(run.generation, 'better', lambda r: 11)
    assert (book.current, book.version, book.stamp_ns) == ('better', 2, 11)
    book.set_faults({'right_arm_joint2': Fault()})     # a new fault supersedes it
    assert not book.publish_refined(run.generation, 'stale', lambda r: 12)
    assert book.current == 'better'
    book.refined(run.generation)


def test_a_run_whose_refinement_follows_stays_running_until_refined():
    book = RunBook()
    book.set_faults({'right_arm_joint1': Fault()})
    run = book.next_run(timeout=1.0)
    book.refinement_follows(run.generation)
    book.publish(run.generation, 'first', lambda r: 10)
    assert book.snapshot()['running']                  # no gap before the refinement
    assert book.refining(run.generation) == 1
    book.refined(run.generation)
    assert not book.snapshot()['running']
    book.set_faults({'right_arm_joint2': Fault()})     # without a refinement to follow
    run = book.next_run(timeout=1.0)
    book.publish(run.generation, 'second', lambda r: 20)
    assert not book.snapshot()['running']


def test_a_new_request_cancels_a_refinement():
    cancelled = []
    book = RunBook(on_request=lambda: cancelled.append(True))
    book.set_faults({'right_arm_joint1': Fault()})
    run = book.next_run(timeout=1.0)
    book.publish(run.generation, 'first', lambda r: 10)
    assert book.refining(run.generation)
    book.request()
    assert cancelled == [True]


def test_the_keeper_builds_persists_and_reuses_its_table(robot, product_library, tmp_path):
    logs = []
    keeper = ContingencyKeeper(robot, product_library, tmp_path, lambda *a: logs.append(a),
                               seeds=(0,))
    settings = RecoverySettings()
    path = tmp_path / TABLE_FILE
    try:
        keeper.configure(settings)
        end = time.monotonic() + 120.0
        while keeper.entries < 14 and time.monotonic() < end:
            time.sleep(0.1)
        assert keeper.entries == 14, logs
        hit = keeper.lookup({'right_arm_joint2': None}, settings)
        assert hit.origin == 'table' and hit.faults == {'right_arm_joint2': None}
        assert keeper.lookup({'right_arm_joint2': 0.1}, settings) is None      # another lock
        other = settings.with_changes(continuity_weight=0.5)
        assert keeper.lookup({'right_arm_joint2': None}, other) is None        # other settings
    finally:
        keeper.stop()
    assert len(json.loads(path.read_text())['entries']) == 14
    again = ContingencyKeeper(robot, product_library, tmp_path, lambda *a: logs.append(a))
    try:
        again.configure(settings)
        end = time.monotonic() + 10.0
        while again.entries < 14 and time.monotonic() < end:
            time.sleep(0.05)
        assert again.entries == 14 and not again.building
        assert replace(again.lookup({'right_arm_joint2': None}, settings), faults={}) \
            == replace(hit, faults={})
    finally:
        again.stop()


def _state(pid):
    """Return the process state letter of ``pid`` (``T``: stopped)."""
    with open(f'/proc/{pid}/stat') as stat:
        return stat.read().rsplit(')', 1)[1].split()[0]


def _stopped(pid, timeout=5.0):
    """Return whether ``pid`` is stopped, waiting up to ``timeout`` s for it to become so."""
    end = time.monotonic() + timeout
    while _state(pid) != 'T' and time.monotonic() < end:
        time.sleep(0.01)
    return _state(pid) == 'T'


def _report_parent(conn, parent_pid):
    die_with_parent(parent_pid)
    conn.send('alive')


def test_a_child_whose_parent_is_already_gone_exits_at_once():
    ctx = multiprocessing.get_context('spawn')
    for parent_pid, alive in ((os.getpid(), True), (1, False)):
        mine, theirs = ctx.Pipe()
        proc = ctx.Process(target=_report_parent, args=(theirs, parent_pid))
        proc.start()
        theirs.close()
        proc.join(timeout=60.0)
        assert proc.exitcode == 0
        try:
            said = mine.recv()
        except EOFError:
            said = None
        assert (said == 'alive') is alive


def test_the_keeper_stops_its_builder_only_once_it_is_armed(robot, product_library, tmp_path):
    # A builder stopped before it armed its death signal would outlive a killed node: a
    # pause at once after the start leaves it running until it is armed.
    logs = []
    keeper = ContingencyKeeper(robot, product_library, tmp_path, lambda *a: logs.append(a),
                               seeds=(0,))
    try:
        keeper.configure(RecoverySettings())
        end = time.monotonic() + 60.0
        while keeper.builder_pid is None and time.monotonic() < end:
            time.sleep(0.001)
        pid = keeper.builder_pid
        assert os.getpriority(os.PRIO_PROCESS, pid) == 19     # its start-up too
        keeper.pause()                              # a live run begins as it starts
        while not keeper.armed and time.monotonic() < end:
            time.sleep(0.05)
        assert keeper.armed, logs                   # it was not stopped while starting
        assert _stopped(pid)                        # armed, it is stopped for the live run
        keeper.resume()
        assert _state(pid) != 'T'
        keeper.pause()
        assert _stopped(pid)
        keeper.resume()
        assert _state(pid) != 'T'
    finally:
        keeper.stop()
