"""
The node processes that the demos, the node benchmarks and the tests start.

``demo``, ``demo-play``, ``bench latency --start-node``, ``bench stream --start-node``
and ``bench product`` start a ``recovery_node`` (and the player, the simulator) as
child processes.  A private node runs in its own domain (``70 + pid % 30`` unless one
is given) and, with a namespace, under ``--ros-args -r __ns:=NS``; its state goes to a
temporary directory and its output to a log that is shown when it does not stop
cleanly.  Free of ROS: only subprocesses.
"""

from dataclasses import dataclass
import os
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import tempfile
from typing import Optional

STOP_TIMEOUT_SEC = 15.0    # SIGINT, then this long for a clean exit, then SIGKILL


def executable_command(name, module):
    """Return the command that starts the console script ``name`` (else ``-m module``)."""
    beside = Path(sys.executable).parent / name
    if beside.is_file():
        return [str(beside)]
    found = shutil.which(name)
    if found:
        return [found]
    return [sys.executable, '-m', module]


def node_command():
    """Return the command that starts the ``recovery_node`` executable."""
    return executable_command('recovery_node', 'namo_fault_recovery.ros.recovery_node')


def player_command():
    """Return the command that starts the ``gesture_player`` executable."""
    return executable_command('gesture_player', 'namo_fault_recovery.ros.player_node')


def private_domain():
    """
    Return a domain id for a private node: 222-232, away from the usual 0 and from tests.

    The top of ROS 2's usable ids on Linux (232): their ports lie above the ephemeral
    range, and the test suite's domains (1-221, ``test/node_harness.py``) never reach
    them, so a benchmark's node never answers a test's client, nor the other way round.
    """
    return 222 + os.getpid() % 11


def stop_process(proc, sig=signal.SIGINT, timeout=STOP_TIMEOUT_SEC):
    """Stop ``proc`` with ``sig`` (SIGKILL if it is not gone in ``timeout`` s); return its code."""
    if proc.poll() is None:
        proc.send_signal(sig)
        try:
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return proc.returncode


def start_logged(command, ros_args, domain_id, log_path, env=None):
    """
    Start ``command --ros-args ros_args`` in ``domain_id``, its output to ``log_path``.

    Returns ``(process, log file)``; the log is opened ``w+b`` so that it can be read
    back once the process stopped (:func:`read_log`).
    """
    log = open(log_path, 'w+b')
    cmd = list(command) + (['--ros-args'] + list(ros_args) if ros_args else [])
    env = dict(os.environ if env is None else env, ROS_DOMAIN_ID=str(domain_id),
               PYTHONUNBUFFERED='1')
    return subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env), log


def read_log(log):
    """Return what a log of :func:`start_logged` holds, and close it."""
    log.flush()
    log.seek(0)
    text = log.read().decode(errors='replace')
    log.close()
    return text


def node_ros_args(state_dir, namespace='/', robot_file=None, gesture_file=None,
                  params=()):
    """Return the ``--ros-args`` of a private node: namespace, state, model files, params."""
    ros_args = ['-p', f'state_dir:={state_dir}']
    if namespace.strip('/'):
        ros_args = ['-r', f'__ns:={namespace}'] + ros_args
    for option, value in (('robot_file', robot_file), ('gesture_file', gesture_file)):
        if value:
            ros_args += ['-p', f'{option}:={os.path.abspath(value)}']
    for param in params:
        ros_args += ['-p', param]
    return ros_args


class PrivateNode:
    """The node as a subprocess with a temporary state directory; a context manager."""

    def __init__(self, domain_id, namespace='/', out=None, robot_file=None,
                 gesture_file=None, params=()):
        """Start the node; ``params`` are ``NAME:=VALUE`` parameters."""
        self.domain_id = domain_id
        self.workdir = tempfile.mkdtemp(prefix='namo_node_')
        ros_args = node_ros_args(self.workdir, namespace, robot_file, gesture_file, params)
        if out is not None:
            cmd = node_command() + ['--ros-args'] + ros_args
            out.write(f"starting the node: {' '.join(cmd)} (ROS_DOMAIN_ID={domain_id})\n")
        self.proc, self._log = start_logged(node_command(), ros_args, domain_id,
                                            os.path.join(self.workdir, 'node.log'))
        self.returncode = None
        self.log = ''

    @classmethod
    def for_args(cls, args, domain_id, namespace='/', out=None, extra_params=()):
        """Start one from a command's ``robot_file``, ``gesture_file`` and ``node_params``."""
        return cls(domain_id, namespace, out, getattr(args, 'robot_file', None),
                   getattr(args, 'gesture_file', None),
                   list(getattr(args, 'node_params', None) or ()) + list(extra_params))

    def stop(self):
        """Stop the node with SIGINT (SIGKILL after 15 s); return its exit code."""
        if self.returncode is not None:
            return self.returncode
        self.returncode = stop_process(self.proc)
        self.log = read_log(self._log)
        shutil.rmtree(self.workdir, ignore_errors=True)
        return self.returncode

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()


@dataclass(frozen=True)
class NodeTarget:
    """
    The node a benchmark measures: one already running, or a private one it starts.

    ``start_node`` False measures the node running in ``domain_id`` (None:
    ``$ROS_DOMAIN_ID``).  True starts a private node in ``domain_id`` (None: a private
    one) that loads ``robot_file`` and ``gesture_file`` (None: the packaged ones) with
    the ``NAME:=VALUE`` parameters ``node_params``.
    """

    start_node: bool = False
    domain_id: Optional[int] = None
    robot_file: Optional[str] = None
    gesture_file: Optional[str] = None
    node_params: tuple = ()

    @classmethod
    def from_args(cls, args):
        """Return a command's target (``--start-node``, ``--domain-id``, files, params)."""
        return cls(bool(getattr(args, 'start_node', False)), getattr(args, 'domain_id', None),
                   getattr(args, 'robot_file', None), getattr(args, 'gesture_file', None),
                   tuple(getattr(args, 'node_params', None) or ()))

    def start(self, namespace='/', out=None, extra_params=()):
        """Return ``(PrivateNode or None, domain id)``: the node started, where to reach it."""
        if not self.start_node:
            return None, self.domain_id
        domain = private_domain() if self.domain_id is None else self.domain_id
        return PrivateNode(domain, namespace, out, self.robot_file, self.gesture_file,
                           list(self.node_params) + list(extra_params)), domain
