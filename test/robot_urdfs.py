"""
The test robots' URDFs inside the example-robot-data wheel (the ``robots`` extra).

One place for their paths and for the skip of a test that needs one where the extra is
not installed (CI installs it, so these tests run there).
"""

import pytest

DISTRIBUTION = 'example-robot-data'
URDFS = {'talos': 'talos_data/robots/talos_reduced.urdf',
         'tiago_dual': 'tiago_description/robots/tiago_dual.urdf',
         'baxter': 'baxter_description/urdf/baxter.urdf'}
TALOS_URDF = URDFS['talos']
TIAGO_URDF = URDFS['tiago_dual']


def installed_urdf(name='talos'):
    """Return the path of robot ``name``'s URDF; skip the calling test without the wheel."""
    from namo_fault_recovery.resources import distribution_file
    try:
        return distribution_file(DISTRIBUTION, URDFS[name])
    except FileNotFoundError:
        pytest.skip(f'{DISTRIBUTION} (the {name} URDF) is not installed')
