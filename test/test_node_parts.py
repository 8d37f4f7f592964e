"""Fast unit tests of the node's ROS-free parts: run book, fault intake, restore, diagnostics."""

from dataclasses import replace
import math
import threading

from namo_fault_recovery.recovery.engine import RecoverySettings
from namo_fault_recovery.recovery.result import (GestureResult, LibraryResult,
                                                 reference_result, summary)
from namo_fault_recovery.ros import diagnostics
from namo_fault_recovery.ros.node import reconfigure_answer
from namo_fault_recovery.ros.parameters import check_parameter, node_config, parameter_specs
from namo_fault_recovery.runtime.demand_tick import DemandTick
from namo_fault_recovery.runtime.fault_intake import Clear, FaultIntake, Report
from namo_fault_recovery.runtime.inputs import BadInput, MAX_REASON, parse_fault
from namo_fault_recovery.runtime.restore import check_result, restore_decision
from namo_fault_recovery.runtime.run_book import Outcome, RunBook
from namo_fault_recovery.runtime.state_store import Fault, PersistedState
import pytest


def _defaults():
    return {name: default for name, default, _ in parameter_specs()}


# --- run book ---------------------------------------------------------------------------

def test_a_stale_run_is_never_published():
    book = RunBook()
    book.set_faults({'right_arm_joint1': Fault()})
    run = book.next_run(timeout=1.0)
    book.set_faults({'right_arm_joint2': Fault()})      # supersedes the run under way
    published = []
    assert book.publish(run.generation, 'old', lambda r: published.append(r) or 1) is None
    assert published == []
    newer = book.next_run(timeout=1.0)
    assert newer.generation > run.generation and 'right_arm_joint2' in newer.faults
    ready = book.publish(newer.generation, 'new', lambda r: published.append(r) or 2)
    assert ready == [] and published == ['new'] and book.version == 1


def test_every_caller_is_told_once_without_blocking():
    book = RunBook()
    told = []
    for _ in range(50):
        book.call(told.append)                       # returns at once
    assert told == []
    run = book.next_run(timeout=1.0)
    book.call(told.append)                           # joins the pending generation
    ready = book.publish(run.generation, 'lib', lambda r: 7)
    book.notify(ready)
    assert len(told) == 51 and all(o.published and o.version == 1 for o in told)
    assert book.next_run(timeout=0.01) is None       # nothing more was requested


def test_a_call_after_publication_runs_again_and_stop_tells_waiters():
    book = RunBook()
    told = []
    book.request()
    run = book.next_run(timeout=1.0)
    book.notify(book.publish(run.generation, 'lib', lambda r: 1))
    book.call(told.append)
    assert book.next_run(timeout=1.0) is not None    # a new run for the same fault set
    book.stop()
    assert len(told) == 1 and not told[0].published and 'shutting down' in told[0].reason
    book.call(told.append)
    assert len(told) == 2 and not told[1].published


def test_a_failed_run_answers_its_callers_and_keeps_the_library():
    book = RunBook()
    told = []
    book.call(told.append)
    run = book.next_run(timeout=1.0)
    book.notify(book.failed(run.generation, 'boom'))
    assert told[0].published is False and 'boom' in told[0].reason


def test_a_request_cancels_the_run_under_way():
    cancels = []
    book = RunBook(on_request=lambda: cancels.append(1))
    book.request()
    assert cancels == []                             # nothing was running
    book.next_run(timeout=1.0)
    book.request()
    assert cancels == [1]


# --- fault intake -------------------------------------------------------------------------

def test_intake_persists_before_it_acknowledges_and_keeps_order():
    book = RunBook()
    events = []

    def commit(faults):
        events.append(('persist', dict(faults)))
        book.set_faults(faults)

    def accepted(reports, cleared, faults):
        events.append(('accepted', len(reports), cleared, dict(faults)))

    intake = FaultIntake(book, commit, accepted, measured=lambda: {'right_arm_joint1': 0.5})
    done = threading.Event()
    for k in range(1000):
        intake.submit(Report({'right_arm_joint1': k * 1e-4}))
    intake.submit(Report({'right_arm_joint2': None}))
    intake.submit(Clear(lambda count: done.set()))
    intake.submit(Report({'left_arm_joint3': 0.1}))
    intake.start()
    try:
        assert done.wait(5.0)
        for _ in range(100):
            if book.faults.get('left_arm_joint3'):
                break
            threading.Event().wait(0.01)
    finally:
        intake.stop()
    assert events[0][0] == 'persist'
    for first, second in zip(events, events[1:]):
        if second[0] == 'accepted':
            assert first[0] == 'persist' and first[1] == second[3]
    assert book.faults == {'left_arm_joint3': Fault(0.1, None)}


def test_reports_alone_are_acknowledged_once_their_library_is_out(monkeypatch, library):
    from namo_fault_recovery.runtime import fault_intake
    monkeypatch.setattr(fault_intake, 'SETTLE_SEC', 30.0)   # only the publication ends it
    book = RunBook()
    pending_when_accepted, cleared = [], threading.Event()
    intake = FaultIntake(book, book.set_faults,
                         lambda reports, *_: pending_when_accepted.append(book.pending()))

    def dispatcher():
        run = book.next_run(timeout=5.0)
        book.publish(run.generation, reference_result(library), lambda result: 1)

    publisher = threading.Thread(target=dispatcher)
    publisher.start()
    intake.start()
    try:
        intake.submit(Report({'right_arm_joint1': 0.1}))
        publisher.join(5.0)
        # A clear is answered at once: its caller registers for the library it asked for.
        intake.submit(Clear(lambda count: cleared.set()))
        assert cleared.wait(5.0)
    finally:
        intake.stop()
    assert pending_when_accepted == [False, True]


def test_intake_keeps_the_first_measured_angle_of_a_joint_reported_again():
    book = RunBook()
    measured = {'right_arm_joint1': 0.25}
    accepted = threading.Semaphore(0)
    intake = FaultIntake(book, book.set_faults, lambda *a: accepted.release(),
                         measured=lambda: dict(measured))
    intake.start()
    try:
        intake.submit(Report({'right_arm_joint1': None}))
        assert accepted.acquire(timeout=5.0)
        measured['right_arm_joint1'] = 0.9
        intake.submit(Report({'right_arm_joint1': None}))
        assert accepted.acquire(timeout=5.0)
    finally:
        intake.stop()
    assert book.faults['right_arm_joint1'] == Fault(None, 0.25)


# --- inputs are bounded ---------------------------------------------------------------------

def test_a_huge_joint_name_gives_a_bounded_reason(robot):
    with pytest.raises(BadInput) as err:
        parse_fault(robot, ['x' * 10_000_000])
    assert len(str(err.value)) < MAX_REASON + 40


def test_a_lock_within_tolerance_is_clamped_to_the_limit_exactly(robot):
    side, index = robot.locate_joint('right_arm_joint1')
    upper = float(robot.arms[side].upper[index])
    parsed = parse_fault(robot, ['right_arm_joint1'], [upper + 5e-10])
    assert parsed['right_arm_joint1'] == upper


def test_parameter_reasons_are_bounded():
    reason = check_parameter('lock_strategy', 'y' * 100_000)
    assert reason.startswith('lock_strategy') and len(reason) < 400


def test_node_config_holds_the_engine_settings_by_name():
    config = node_config(_defaults())
    assert config.settings == RecoverySettings()
    assert config.seed is None
    changed = node_config(dict(_defaults(), vq_distortion_mm=30.0, seed=4,
                               **{'weights.palm': 2.0}))
    assert changed.settings.vq_distortion_mm == 30.0 and changed.seed == 4
    assert changed.settings.weights.palm == 2.0


# --- restore and checks ---------------------------------------------------------------------

def test_restore_decision(robot, library):
    ref = reference_result(library, 1.0, RecoverySettings().public())
    state = PersistedState({}, ref, 'fp')
    assert restore_decision(robot, library, state, 'fp', RecoverySettings()) is None
    assert 'changed' in restore_decision(robot, library, state, 'other', RecoverySettings())
    faulted = PersistedState({'right_arm_joint1': Fault()}, ref, 'fp')
    assert 'another fault set' in restore_decision(robot, library, faulted, 'fp',
                                                   RecoverySettings())


def test_check_result_refuses_an_angle_beyond_the_limit_by_any_amount(robot, library):
    ref = reference_result(library)
    assert check_result(robot, library, ref) is None
    side, index = robot.locate_joint('right_arm_joint1')
    upper = float(robot.arms[side].upper[index])
    g = ref.gestures[0]
    bad = tuple((upper + 5e-10,) + tuple(q[1:]) for q in g.positions)
    broken = replace(ref, gestures=(replace(g, positions=bad),) + ref.gestures[1:])
    assert 'outside its limits' in check_result(robot, library, broken)


# --- diagnostics ----------------------------------------------------------------------------

def test_diagnostics_from_a_snapshot(robot, library):
    settings = node_config(_defaults()).settings
    snap = diagnostics.Snapshot(
        faults={'right_arm_joint2': Fault()}, fault_version=3, current=reference_result(library),
        version=2, stamp_ns=5, pending=True, running=True, failed=None, settings=settings,
        rejections=[(0.0, '/actuator_fault', 'bad')], rejected_total=1)
    out = {s.name: s for s in diagnostics.statuses(robot, snap, 'robot1/recovery_node: ')}
    faults = out['robot1/recovery_node: faults']
    assert {kv.key: kv.value for kv in faults.values}['failed_joints'] == 'right_arm_joint2'
    recon = {kv.key: kv.value for kv in out['robot1/recovery_node: reconfiguration'].values}
    assert recon['library_version'] == '2' and recon['up_to_date'] == 'false'
    assert recon['running'] == 'true'
    inputs = {kv.key: kv.value for kv in out['robot1/recovery_node: inputs'].values}
    assert inputs['rejected_total'] == '1'
    assert diagnostics.status_prefix('/recovery_node') == 'recovery_node: '
    assert math.isfinite(float(recon['wall_time_sec']))


# --- answer pacer -----------------------------------------------------------------------------

def test_answer_bucket_lets_a_burst_go_then_one_per_gap():
    from namo_fault_recovery.runtime.answer_pacer import Bucket
    burst, gap = 4, 0.01
    bucket, now, sends = Bucket(burst, gap), 100.0, []
    for _ in range(50):                  # a greedy sender: each answer as soon as allowed
        now += bucket.wait(now)
        assert bucket.wait(now) == 0.0
        bucket.take(now)
        sends.append(now)
    assert sends[:burst] == [100.0] * burst and sends[burst] > 100.0
    for i, start in enumerate(sends):     # what a reader can find in any window
        for span in (0.0, gap / 2, gap, 5 * gap, 0.2):
            count = sum(1 for t in sends[i:] if t <= start + span + 1e-12)
            assert count <= burst + span / gap + 1e-9, (start, span, count)
    assert abs(sends[-1] - (100.0 + (50 - burst) * gap)) < 1e-9
    now = sends[-1] + 10 * gap                          # quiet: the burst is back, no more
    assert bucket.wait(now) == 0.0
    for _ in range(burst):
        bucket.take(now)
    assert bucket.wait(now) > 0.0


def test_answer_pacer_releases_every_answer_in_order_one_at_a_time():
    from namo_fault_recovery.runtime.answer_pacer import AnswerPacer
    released, problems, sent = [], [], []
    ready = threading.Condition()

    def release(k):
        with ready:
            if len(released) != len(sent):   # the previous answer not reported sent yet
                problems.append(k)
            released.append(k)
            ready.notify()

    wakes = []
    pacer = AnswerPacer(lambda: wakes.append(1), burst=4, gap=0.0005, sent_timeout=30.0)
    for k in range(50):
        pacer.submit(lambda k=k: release(k))
    pacer.start()
    with ready:                          # the executor's part: send each answer, say so
        while len(sent) < 50:
            assert ready.wait_for(lambda: len(released) > len(sent), timeout=30.0)
            sent.append(released[len(sent)])
            pacer.sent()
    pacer.stop()
    assert released == list(range(50)) and not problems and len(wakes) == 50
    pacer.submit(lambda: released.append('late'))      # after stop: released at once
    assert released[-1] == 'late'


def test_answer_pacer_goes_on_when_an_answer_is_never_reported_sent():
    from namo_fault_recovery.runtime.answer_pacer import AnswerPacer
    released = []
    pacer = AnswerPacer(lambda: None, burst=4, gap=0.0005, sent_timeout=0.01)
    for k in range(5):
        pacer.submit(lambda k=k: released.append(k))
    pacer.start()
    for _ in range(3000):
        if len(released) == 5:
            break
        threading.Event().wait(0.01)
    pacer.stop()
    assert released == list(range(5))


# --- background state writer ------------------------------------------------------------------

def test_background_writer_never_writes_an_older_snapshot_over_a_newer_one(tmp_path):
    from namo_fault_recovery.runtime.state_store import BackgroundWriter, decode_state, StateStore
    store = StateStore(tmp_path)
    store.save({'right_arm_joint1': Fault(0.1)}, None, 'fp', seq=5)     # a fault commit
    writer = BackgroundWriter(lambda faults, library, seq: store.save(faults, library,
                                                                      'fp', seq))
    writer.start()
    writer.submit({}, None, 3)            # an older library snapshot: dropped
    assert writer.flush()
    assert list(decode_state(store.path.read_text()).faults) == ['right_arm_joint1']
    writer.submit({'left_arm_joint2': Fault(0.2)}, None, 6)
    writer.stop()                         # writes what is pending first
    assert list(decode_state(store.path.read_text()).faults) == ['left_arm_joint2']


# --- the publish path: the fault set's write overlaps the run; nothing is published before ---

def test_a_fault_set_being_written_starts_the_run_but_is_published_only_once_on_disk(
        tmp_path, robot, library):
    from namo_fault_recovery.runtime.persistence import Persistence
    from namo_fault_recovery.runtime.state_store import StateStore
    book = RunBook()
    state = Persistence(tmp_path, robot, library, book, on_error=lambda text: None)
    saving, release, order = threading.Event(), threading.Event(), []
    journal = state.store.journal
    real_sync = journal.sync

    def slow_sync(*args, **kwargs):
        saving.set()
        assert release.wait(5.0)
        real_sync(*args, **kwargs)
        order.append('synced')

    journal.sync = slow_sync
    faults = {'right_arm_joint1': Fault(0.1)}
    committer = threading.Thread(target=state.commit_faults, args=(faults, 0.0))
    committer.start()
    assert saving.wait(5.0)
    run = book.next_run(timeout=5.0)                  # the run starts during the write
    assert run is not None and run.faults == faults
    assert book.snapshot()['faults'] == {}            # not shown before it is on disk
    publisher = threading.Thread(target=state.publish_and_queue, args=(
        run.generation, faults, reference_result(library),
        lambda result: order.append('published') or 1, 0.0))
    publisher.start()
    publisher.join(0.2)
    assert order == []                                # publication waits for the write
    release.set()
    committer.join(5.0)
    publisher.join(5.0)
    assert order == ['synced', 'published']
    snap = book.snapshot()
    assert snap['faults'] == faults and snap['fault_sync'] >= 0.0
    assert snap['fault_to_request'] >= 0.0 and snap['publish_path'] >= 0.0
    # On disk before the publication, as a restart reads it (no state file written yet:
    # its writer was never started).
    assert not state.store.path.exists()
    assert StateStore(tmp_path).load()[0].faults == faults


@pytest.mark.parametrize('step', ['write', 'sync'])
def test_a_journal_that_fails_falls_back_to_the_state_file_and_says_so_once(
        tmp_path, robot, library, step):
    """Either half of the journal's append failing: the state file is rewritten instead."""
    from namo_fault_recovery.runtime.persistence import Persistence
    from namo_fault_recovery.runtime.state_store import StateStore
    errors = []
    state = Persistence(tmp_path, robot, library, RunBook(), on_error=errors.append)

    def broken(*args):
        raise OSError('disk full')

    setattr(state.store.journal, step, broken)
    for angle in (0.1, 0.2):
        state.commit_faults({'right_arm_joint1': Fault(angle)})
        assert StateStore(tmp_path).load()[0].faults == {'right_arm_joint1': Fault(angle)}
    assert len(errors) == 1 and 'cannot append to the fault journal' in errors[0]
    assert 'disk full; rewriting the state file instead' in errors[0]


def test_fault_to_publish_spans_a_report_to_the_first_library_after_it(library):
    import time
    book = RunBook()
    received = time.monotonic()
    book.set_faults({'right_arm_joint1': Fault(0.1)}, received_at=received)
    book.request()                                   # a newer request joins the report
    run = book.next_run(timeout=1.0)
    before = time.monotonic()
    assert book.publish(run.generation, reference_result(library), lambda r: 1) is not None
    first = book.snapshot()['fault_to_publish']
    assert before - received <= first <= time.monotonic() - received
    book.request()                                   # e.g. /reconfigure_gestures: no report
    run = book.next_run(timeout=1.0)
    book.publish(run.generation, reference_result(library), lambda r: 2)
    assert book.snapshot()['fault_to_publish'] == first


def test_the_state_file_follows_the_publication_and_empties_the_journal(tmp_path, robot, library):
    from namo_fault_recovery.runtime.persistence import Persistence
    from namo_fault_recovery.runtime.state_store import decode_state, StateStore
    book = RunBook()
    state = Persistence(tmp_path, robot, library, book, on_error=lambda text: None)
    state.start()
    faults = {'left_arm_joint3': Fault(-0.2, 0.1)}
    state.commit_faults(faults)
    assert not state.store.path.exists()              # nothing published yet
    run = book.next_run(timeout=1.0)
    assert state.publish_and_queue(run.generation, faults, reference_result(library),
                                   lambda result: 1) is not None
    state.stop()                                      # writes what is queued
    assert decode_state(state.store.path.read_text()).faults == faults
    assert state.store.journal.path.read_bytes() == b''
    # A restarted node numbers its changes above those on disk.
    again = Persistence(tmp_path, robot, library, RunBook(), on_error=lambda text: None)
    again.commit_faults({})
    stored = StateStore(tmp_path).load()[0]
    assert stored.faults == {} and stored.seq > decode_state(
        state.store.path.read_text()).seq
    again.stop()


def test_an_unwritable_journal_falls_back_to_the_state_file(tmp_path, robot, library):
    from namo_fault_recovery.runtime.persistence import Persistence
    from namo_fault_recovery.runtime.state_store import decode_state
    errors = []
    state = Persistence(tmp_path, robot, library, RunBook(), on_error=errors.append)
    state.store.journal.path.mkdir()                  # cannot be opened as a file
    faults = {'right_arm_joint7': Fault(0.3)}
    state.commit_faults(faults)
    state.commit_faults(faults)
    assert decode_state(state.store.path.read_text()).faults == faults
    assert len(errors) == 1 and 'fault journal' in errors[0]
    state.stop()


def test_diagnostics_show_the_publish_path_figures(robot, library):
    settings = node_config(_defaults()).settings
    snap = diagnostics.Snapshot(
        faults={}, fault_version=1, current=reference_result(library), version=1,
        stamp_ns=5, pending=False, running=False, failed=None, settings=settings,
        publish_path=0.0012, fault_to_request=0.0003, fault_sync=0.004)
    out = {s.name: s for s in diagnostics.statuses(robot, snap, 'recovery_node: ')}
    recon = {kv.key: kv.value for kv in out['recovery_node: reconfiguration'].values}
    assert float(recon['publish_path_sec']) == pytest.approx(0.0012)
    assert float(recon['fault_to_request_sec']) == pytest.approx(0.0003)
    assert float(recon['fault_sync_sec']) == pytest.approx(0.004)


def test_latest_worker_runs_the_newest_item_and_drops_the_superseded():
    from namo_fault_recovery.runtime.latest_worker import LatestWorker
    done, seen = threading.Event(), []
    worker = LatestWorker(lambda *item: (seen.append(item), done.set()), delay=0.0)
    for k in range(3):
        worker.submit(k, 'stamp')                     # before start: they collapse
    worker.start()
    try:
        assert done.wait(5.0)
    finally:
        worker.stop()
    assert seen == [(2, 'stamp')]


# --- what a deadline result and a refined one say -----------------------------------------

def _deadline_result():
    wai = GestureResult(name='wai', times=(0.0,), positions=((0.0,) * 14,), score_before=61.96,
                        score_after=25.67, wall_time=0.08, status='converged')
    return LibraryResult(gestures=(wai,), faults={'right_arm_joint2': None},
                         locks={'right_arm_joint2': 0.0}, wall_time=0.08, deadline=1.0,
                         deadline_met=True, origin='deadline')


def _refined_result():
    first = _deadline_result()
    wai = replace(first.gestures[0], score_after=25.12, wall_time=0.09)
    return replace(first, gestures=(wai,), wall_time=0.09, origin='refined',
                   refined_after=7.761, refines_version=4)


def test_a_deadline_result_says_its_run_time_and_its_deadline():
    text = summary(_deadline_result())
    assert text.startswith('reconfigured 1/1 gestures in 0.080 s (deadline 1.000 s met) '
                           'for right_arm_joint2 at 0.00 deg by a live search: '), text
    assert text.endswith('wai 61.96 -> 25.67 in 0.080 s'), text
    missed = summary(replace(_deadline_result(), deadline_met=False, success=False))
    assert '(deadline 1.000 s MISSED, best found so far used)' in missed, missed


def test_a_refined_result_says_the_refinement_time_and_the_deadline_apart():
    text = summary(_refined_result())
    assert text.startswith('reconfigured 1/1 gestures refined 7.761 s after the deadline '
                           'result (deadline 1.000 s met by version 4) for '
                           'right_arm_joint2 at 0.00 deg: '), text
    assert 'deadline 7.761' not in text and 'in 0.090 s (' not in text, text
    assert text.endswith('wai 61.96 -> 25.12 in 0.090 s'), text
    answer = reconfigure_answer(Outcome(True, _refined_result(), 5, 1_000_000_001))
    assert answer.startswith(text) and answer.endswith('[library version 5, stamp 1.000000001]')
    unknown = summary(replace(_refined_result(), refines_version=0, deadline_met=False))
    assert '(deadline 1.000 s missed by the deadline result)' in unknown, unknown


def test_a_refined_result_keeps_its_figures_through_the_state_file_format():
    refined = _refined_result()
    doc = refined.to_dict()
    assert (doc['deadline'], doc['refined_after'], doc['refines_version']) == (1.0, 7.761, 4)
    assert LibraryResult.from_dict(doc) == refined
    # A file written before the fields: its refined version names no misread deadline.
    old = {k: v for k, v in doc.items() if k not in ('refined_after', 'refines_version')}
    old['deadline'] = 7.761                # what such files held: the refinement's budget
    text = summary(LibraryResult.from_dict(old))
    assert 'refined in the background after the deadline result' in text, text
    assert '7.761' not in text, text


def test_diagnostics_of_a_refined_library_give_the_refinement_time(robot):
    settings = node_config(_defaults()).settings
    snap = diagnostics.Snapshot(
        faults={'right_arm_joint2': Fault()}, fault_version=1, current=_refined_result(),
        version=5, stamp_ns=5, pending=False, running=False, failed=None, settings=settings)
    out = {s.name: s for s in diagnostics.statuses(robot, snap, 'recovery_node: ')}
    status = out['recovery_node: reconfiguration']
    recon = {kv.key: kv.value for kv in status.values}
    assert recon['library_origin'] == 'refined' and recon['deadline_met'] == 'true'
    assert float(recon['refined_after_sec']) == pytest.approx(7.761)
    assert 'refined 7.761 s after the deadline result' in status.message
    snap = replace(snap, current=_deadline_result())
    out = {s.name: s for s in diagnostics.statuses(robot, snap, 'recovery_node: ')}
    assert 'refined_after_sec' not in {kv.key for kv in
                                       out['recovery_node: reconfiguration'].values}


class _Timer:
    """A timer's ``cancel()`` and ``reset()``, counted."""

    def __init__(self):
        self.cancels = self.resets = 0

    def cancel(self):
        self.cancels += 1

    def reset(self):
        self.resets += 1


def test_demand_tick_stops_without_work_and_restarts_once_per_stop():
    pending, runs, wakes = [], [], []
    tick = DemandTick(lambda: runs.append(tick.take_change()), lambda: bool(pending))
    timer = _Timer()
    tick.attach(timer, lambda: wakes.append(1))
    tick.tick()                                   # the first tick takes the initial change
    assert runs == [True] and tick.idle and timer.cancels == 1
    tick.wake()
    tick.wake()                                   # already running: nothing more
    assert not tick.idle and timer.resets == 1 and len(wakes) == 1
    pending.append('a sample')
    tick.tick()
    assert not tick.idle and timer.cancels == 1   # work left: keeps ticking
    pending.clear()
    tick.change()                                 # a change arrives while it runs
    tick.tick()
    assert runs[-1] is True and tick.idle and timer.cancels == 2
    tick.change()                                 # a change while stopped restarts it
    assert not tick.idle and timer.resets == 2 and len(wakes) == 2
    tick.tick()
    assert runs[-1] is True and tick.idle and timer.cancels == 3


def test_demand_tick_never_loses_a_change_made_while_it_decides():
    # change() from another thread while the tick decides to stop: it restarts the tick.
    timer, changers = _Timer(), []

    def has_work():                    # called with the tick's lock held
        changers.append(threading.Thread(target=tick.change))
        changers[-1].start()
        changers[-1].join(0.05)        # it waits for the lock
        return False

    tick = DemandTick(lambda: None, has_work)
    tick.attach(timer, lambda: None)
    tick.take_change()
    tick.tick()
    changers[0].join()
    assert (timer.cancels, timer.resets) == (1, 1) and not tick.idle
    assert tick.take_change()


def test_a_start_up_signal_turned_into_an_import_error_is_still_a_clean_stop():
    """An extension being imported wraps the handler's SystemExit (pybind11's ImportError)."""
    from namo_fault_recovery.ros.recovery_node import cut_short_by_signal as cut_short
    try:
        try:
            raise SystemExit(0)
        except SystemExit as stop:
            raise ImportError('initialization failed') from stop
    except ImportError as exc:
        wrapped = exc
    assert cut_short(wrapped) and cut_short(SystemExit(0))
    assert not cut_short(ImportError('a real one')) and not cut_short(ValueError())


def test_a_start_up_signal_swallowed_where_it_landed_prints_nothing():
    """A weakref callback's ignored SystemExit of a start-up signal is not a traceback."""
    from types import SimpleNamespace

    from namo_fault_recovery.ros.recovery_node import swallowed_stop_hook
    passed = []
    stop = SimpleNamespace(exc_type=SystemExit, exc_value=SystemExit(0), object=None)
    other = SimpleNamespace(exc_type=ValueError, exc_value=ValueError('a real one'),
                            object=None)

    class HalfBuilt:
        def __del__(self):
            return self.never_set

    # A finaliser of an object whose constructor the signal cut short (rclpy's executor).
    half = SimpleNamespace(exc_type=AttributeError, exc_value=AttributeError('_sigint_gc'),
                           object=HalfBuilt.__del__)
    swallowed_stop_hook([2], passed.append)(stop)
    swallowed_stop_hook([2], passed.append)(other)
    swallowed_stop_hook([2], passed.append)(half)
    swallowed_stop_hook([], passed.append)(stop)        # no signal came: not ours
    swallowed_stop_hook([], passed.append)(half)
    assert passed == [other, stop, half]
