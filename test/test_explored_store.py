"""The player's explored motions on disk: a round trip, and a bad file named in one line."""

import json

from namo_fault_recovery.runtime.explored_store import load_motions, save_motions, StoredMotion
import pytest

MOTION = StoredMotion('circle', 'right', ('a', 'b'), (0.0, 0.5), ((0.1, 0.2), (0.3, 0.4)),
                      ((0.11, 0.2), (0.31, 0.41)), (0.8, 1.1), 21, 'secant',
                      ('tip_offset',), ((0.2, -0.1, 49.7),))


def test_explored_motions_round_trip(tmp_path):
    path = tmp_path / 'sub' / 'explored.json'
    assert load_motions(path) == {}
    save_motions(path, {'circle': MOTION})
    assert load_motions(path) == {'circle': MOTION}


@pytest.mark.parametrize('edit, words', [
    (lambda doc: doc.update(format='other'), "format 'other'"),
    (lambda doc: doc['motions'][0]['positions'].pop(), 'key motions[0]: 2 times for 2 base'),
    (lambda doc: doc['motions'][0]['base'][0].append(1.0), 'key motions[0]: base: expected 2'),
    (lambda doc: doc['motions'][0].pop('side'), "key motions[0]: 'side'"),
])
def test_a_bad_file_is_a_one_line_error_naming_it(tmp_path, edit, words):
    path = tmp_path / 'explored.json'
    save_motions(path, {'circle': MOTION})
    doc = json.loads(path.read_text())
    edit(doc)
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError) as err:
        load_motions(path)
    assert str(err.value).startswith(f'{path}: ') and words in str(err.value), err.value
    assert '\n' not in str(err.value)


def test_a_file_that_is_not_json_is_named(tmp_path):
    path = tmp_path / 'explored.json'
    path.write_text('{not json')
    with pytest.raises(ValueError, match='explored.json: Expecting property name'):
        load_motions(path)
