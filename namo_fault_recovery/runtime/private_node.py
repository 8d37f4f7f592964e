"""
A private ``recovery_node`` process for ``demo`` and the node benchmarks.

``bench latency --start-node`` and ``bench product`` start one too.  It runs in its own
domain (``70 + pid % 30`` unless one is given) and, with a namespace, under
``--ros-args -r __ns:=NS``; its state goes to a temporary directory and its output
to a log that is shown when it does not stop cleanly.
"""

import os
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import tempfile


def node_command():
    """Return the command that starts the ``recovery_node`` executable."""
    beside = Path(sys.executable).parent / 'recovery_node'
    if beside.is_file():
        return [str(beside)]
    found = shutil.which('recovery_node')
    if found:
        return [found]
    return [sys.executable, '-m', 'namo_fault_recovery.ros.recovery_node']


def private_domain():
    """Return a domain id for a private node, away from the usual 0."""
    return 70 + os.getpid() % 30


class PrivateNode:
    """The node as a subprocess with a temporary state directory; a context manager."""

    def __init__(self, args, domain_id, namespace='/', out=None, extra_ros_args=()):
        self.domain_id = domain_id
        self.workdir = tempfile.mkdtemp(prefix='namo_node_')
        ros_args = ['-p', f'state_dir:={self.workdir}']
        if namespace.strip('/'):
            ros_args = ['-r', f'__ns:={namespace}'] + ros_args
        for option in ('robot_file', 'gesture_file'):
            value = getattr(args, option, None)
            if value:
                ros_args += ['-p', f'{option}:={os.path.abspath(value)}']
        for param in getattr(args, 'node_params', None) or ():
            ros_args += ['-p', param]
        ros_args += list(extra_ros_args)          # e.g. ('-p', 'contingency_table:=false')
        env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), PYTHONUNBUFFERED='1')
        self._log = open(os.path.join(self.workdir, 'node.log'), 'w+b')
        cmd = node_command() + ['--ros-args'] + ros_args
        if out is not None:
            out.write(f"starting the node: {' '.join(cmd)} (ROS_DOMAIN_ID={domain_id})\n")
        self.proc = subprocess.Popen(cmd, stdout=self._log, stderr=subprocess.STDOUT, env=env)
        self.returncode = None
        self.log = ''

    def stop(self):
        """Stop the node with SIGINT (SIGKILL after 15 s); return its exit code."""
        if self.returncode is not None:
            return self.returncode
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._log.flush()
        self._log.seek(0)
        self.log = self._log.read().decode(errors='replace')
        self._log.close()
        shutil.rmtree(self.workdir, ignore_errors=True)
        self.returncode = self.proc.returncode
        return self.returncode

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()
