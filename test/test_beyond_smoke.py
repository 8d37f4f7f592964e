"""Smoke tests of the beyond-the-paper benchmarks: they run and report sane figures."""

import io
import json

from namo_fault_recovery.benchmarks import beyond
from namo_fault_recovery.cli.main import main
import numpy as np


def test_bench_lock_smoke(tmp_path, robot, library):
    out = io.StringIO()
    doc = beyond.bench_lock(out, tmp_path, seeds=1, robot=robot, library=library,
                            joints=['right_arm_joint3'])
    entry = doc[0]
    assert entry['optimal']['total_best'] <= entry['average']['total_best']
    assert abs(entry['average']['lock_deg'] + 5.25) < 1e-9
    assert 'right_arm_joint3' in out.getvalue()
    assert json.loads((tmp_path / 'lock.json').read_text())[0]['joint'] == 'right_arm_joint3'


def test_bench_pairs_smoke(tmp_path, robot, library):
    out = io.StringIO()
    doc = beyond.bench_pairs(out, tmp_path, robot=robot, library=library)
    assert len(doc) == 21
    for d in doc:
        for g, score in d['scores'].items():
            assert np.isfinite(score) and score <= d['before'][g] + 1e-9
    assert 'deadline met in' in out.getvalue()


def test_bench_bimanual_and_collision_smoke(tmp_path, robot, library):
    out = io.StringIO()
    doc = beyond.bench_bimanual(out, tmp_path, seeds=1, robot=robot, library=library)
    assert [d['joint'] for d in doc] == list(robot.arms['right'].joint_names)
    assert all(d['stage2'] <= d['stage1'] + 1e-9 for d in doc)
    counts, results = beyond.bench_collision(out, tmp_path, robot=robot, library=library,
                                             png=False)
    assert len(results) == 112
    assert counts['collision'] <= counts['plain']
    assert 'Fig. 7g' in out.getvalue()


def test_cli_bench_bimanual_runs(tmp_path, capsys):
    code = main(['bench', 'bimanual', '--seeds', '1', '--out', str(tmp_path)], io.StringIO())
    assert code == 0 and (tmp_path / 'bimanual.json').is_file()
