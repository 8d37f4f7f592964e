"""
Locate the package's data files (config, msg_docs) in every way it is installed.

Under a colcon/ament install the files live in ``share/namo_fault_recovery`` and are
found through the ament index.  From a source checkout or a pip install the package's
own directory is used: ``config/`` beside the package, or the copy installed into the
environment's ``share/`` by ``data_files``.
"""

import os
from pathlib import Path
import sys

PACKAGE_NAME = 'namo_fault_recovery'


def _candidate_share_dirs():
    try:
        from ament_index_python.packages import get_package_share_directory
        from ament_index_python.packages import PackageNotFoundError
        try:
            yield Path(get_package_share_directory(PACKAGE_NAME))
        except (PackageNotFoundError, KeyError, ValueError, OSError):
            pass
    except ImportError:
        pass
    # Source checkout (and editable installs): the repository root.
    yield Path(__file__).resolve().parent.parent
    # pip install: data_files land under <prefix>/share/namo_fault_recovery.
    for prefix in dict.fromkeys((sys.prefix, sys.base_prefix, os.environ.get('VIRTUAL_ENV', ''))):
        if prefix:
            yield Path(prefix) / 'share' / PACKAGE_NAME


def share_dir(subdir='config'):
    """Return the first share directory that holds ``subdir``."""
    tried = []
    for base in _candidate_share_dirs():
        if (base / subdir).is_dir():
            return base / subdir
        tried.append(str(base / subdir))
    raise FileNotFoundError(
        f"cannot find the '{subdir}' directory of {PACKAGE_NAME}; looked in: {', '.join(tried)}")


def config_path(name):
    """Return the path of a packaged config file such as ``gestures.yaml``."""
    path = share_dir('config') / name
    if not path.is_file():
        raise FileNotFoundError(f'packaged config file not found: {path}')
    return path


DEFAULT_ROBOT_FILE = 'namo_robot.yaml'
NAMO_PROFILE_FILE = 'namo_profile.yaml'   # Namo as any robot: its URDF plus a profile
DEFAULT_GESTURE_FILE = 'gestures.yaml'      # Namo's four gestures (Table 2, as motions)
PAPER_GESTURE_FILE = 'paper_gestures.yaml'   # the paper's Table 2 poses
# The demo library of motions: the four gestures plus the dense 100-point "draw a circle"
# (``bench motion`` and the dense-motion demos; kept out of the default library so that
# its lock averages stay Table 2's row).
DEMO_MOTION_FILE = 'demo_motions.yaml'


def distribution_file(distribution, name):
    """
    Return the path of a data file shipped inside an installed Python distribution.

    ``name`` is matched against the end of the distribution's recorded file paths (e.g.
    ``talos_data/robots/talos_reduced.urdf`` in ``example-robot-data``, whose URDFs live
    under ``cmeel.prefix/share/...``).  Raises FileNotFoundError naming what is missing.
    """
    from importlib import metadata
    try:
        dist = metadata.distribution(distribution)
    except metadata.PackageNotFoundError:
        raise FileNotFoundError(
            f'Python distribution {distribution!r} is not installed; expected it for '
            f'{name} (pip install {distribution})') from None
    wanted = '/' + name.strip('/')
    for entry in dist.files or ():
        if ('/' + str(entry).replace(os.sep, '/')).endswith(wanted):
            return Path(dist.locate_file(entry))
    raise FileNotFoundError(f'{distribution} {dist.version} has no file {name!r}')
