"""
Run ``recovery_node``'s ``main()`` once per command line, each in a fork of one process.

Why: a refused configuration ends in the node's start-up, before the network; what
costs is each process' interpreter start and imports (rclpy, numpy, scipy), not the
refusal.  This script imports the node's modules once, then forks one child per
command line; each child runs exactly what the console script ``recovery_node`` runs
(``sys.argv`` set, ``sys.exit(main())``) with its stdout and stderr on files of its own
(file descriptors 1 and 2, so rcl's own output is caught too), from a fresh copy of the
module state.  Nothing is shared between the children but the imported code.

Input on stdin: a JSON list of ``[argv, stdout_path, stderr_path]``.  Output on stdout:
a JSON list of exit codes (None for a child that did not exit within the timeout,
which is then killed).  Before it is killed, such a child writes the Python stack of
each of its threads to its stderr file (``faulthandler`` on SIGUSR1), so that a test
failing on it says where the start-up or the refusal stopped.
"""

import faulthandler
import json
import os
import signal
import sys
import time

TIMEOUT_SEC = 60.0


def _child(argv, out_path, err_path):
    """In the fork: run the node's main() as the console script does; never return."""
    code = 1
    try:
        for fd, path in ((1, out_path), (2, err_path)):
            target = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            os.dup2(target, fd)
            os.close(target)
        faulthandler.register(signal.SIGUSR1, all_threads=True)    # see _wait
        from namo_fault_recovery.ros.recovery_node import main
        sys.argv = list(argv)
        try:
            sys.exit(main())
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except BaseException:  # noqa: B902 - the child reports like the interpreter would
        import traceback
        traceback.print_exc()
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)


def _wait(pid, end):
    """Return the exit code of ``pid`` (None, killed, if it runs past ``end``)."""
    while time.monotonic() < end:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return os.waitstatus_to_exitcode(status)
        time.sleep(0.01)
    os.kill(pid, signal.SIGUSR1)        # its threads' stacks to its stderr file
    time.sleep(0.5)
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
    return None


def main():
    """Fork a child per case (all at once); print their exit codes as JSON."""
    cases = json.load(sys.stdin)
    # What the node imports before it reads its configuration: done once, here.
    import namo_fault_recovery.ros.node  # noqa: F401
    import namo_fault_recovery.ros.recovery_node  # noqa: F401
    import namo_fault_recovery.ros.spin  # noqa: F401
    sys.stdout.flush()
    pids = []
    for argv, out_path, err_path in cases:
        pid = os.fork()
        if pid == 0:
            _child(argv, out_path, err_path)
        pids.append(pid)
    end = time.monotonic() + TIMEOUT_SEC
    print(json.dumps([_wait(pid, end) for pid in pids]))


if __name__ == '__main__':
    main()
