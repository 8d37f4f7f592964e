"""
Files written atomically: a reader sees the old content or the new, never half of one.

Free of ROS.  The one way the package replaces a file that another process may read (the
node's state file, the contingency table): the text goes to a temporary file in the same
directory, is flushed and synced, then renamed over the target with ``os.replace``, and
the directory is synced so that the rename itself survives a power cut.
"""

import os
from pathlib import Path
import tempfile


def write_text_atomically(path, text, private=True):
    """
    Replace the file ``path`` with ``text`` (UTF-8) atomically; create its directory.

    ``private`` keeps the file readable by its owner only (``mkstemp``'s 0600, what the
    node's state file has); otherwise it gets the usual permissions of the umask.  Raises
    OSError when the file cannot be written, leaving the old one (and no temporary file).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', suffix='.tmp', dir=path.parent)
    try:
        with os.fdopen(fd, 'w', encoding='utf-8') as handle:
            handle.write(text)
            handle.flush()
            os.fsync(handle.fileno())
        if not private:
            mask = os.umask(0)
            os.umask(mask)
            os.chmod(tmp, 0o666 & ~mask)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    fsync_directory(path.parent)


def fsync_directory(directory):
    """Sync a directory's entries (a rename into it), ignoring systems that cannot."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
