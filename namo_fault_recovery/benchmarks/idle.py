"""
Idle CPU of a private ``recovery_node``, and clean stops (``namo-recovery bench idle``).

**Idle CPU.**  Starts a ``recovery_node`` (default parameters, a temporary state
directory) with ``contingency_table`` off, then on; waits until it is ready (and, with
the table, until the table is built), lets it settle, then reads the CPU time
(``utime + stime`` in ``/proc/PID/stat``) of the node's process tree (the node, its
engine process, a table builder, and the children already reaped) over a window: the
figure is the % of one core.  Nothing talks to the node meanwhile: no client, no
``/joint_states``.  The busiest threads of the node process are listed too
(``/proc/PID/task``), to show where the time goes.

**Clean stops.**  ``--stops N`` starts ``recovery_node`` and ``namo_sim`` N times each,
sends SIGTERM at a random moment of their idle life (0-2 s after they are ready), and
counts those that exit with code 0 within ``STOP_GRACE_SEC`` (a hang is killed).

Free of ROS: only subprocesses and ``/proc`` (Linux).
"""

import os
import random
import shutil
import signal
import subprocess
import tempfile
import time

from .common import BenchError
from ..runtime.private_node import (executable_command, node_command, node_ros_args,
                                    read_log, start_logged)

NODE_READY = 'engine process started'          # the node's last start-up line
TABLE_BUILT = 'entries built in'               # the table builder's last line
SIM_READY = 'simulating '                      # namo_sim's start-up line
STOP_GRACE_SEC = 5.0
CLK_TCK = os.sysconf('SC_CLK_TCK') if hasattr(os, 'sysconf') else 100


def _stat_fields(path):
    """Return the fields of a ``/proc/.../stat`` file after the command name, or None."""
    try:
        text = open(path).read()
    except OSError:
        return None
    return text[text.rindex(')') + 2:].split()


def _comm(path):
    try:
        return open(path).read().strip()
    except OSError:
        return '?'


def process_tree(root):
    """Return the pids of ``root`` and all its descendants (from ``/proc``)."""
    children = {}
    for entry in os.listdir('/proc'):
        if entry.isdigit():
            fields = _stat_fields(f'/proc/{entry}/stat')
            if fields is not None:
                children.setdefault(int(fields[1]), []).append(int(entry))
    tree, todo = [], [root]
    while todo:
        pid = todo.pop()
        tree.append(pid)
        todo.extend(children.get(pid, ()))
    return tree


def tree_ticks(root):
    """Return {pid: (name, CPU ticks)} of the tree; the root's counts reaped children."""
    found = {}
    for pid in process_tree(root):
        fields = _stat_fields(f'/proc/{pid}/stat')
        if fields is None:
            continue
        ticks = int(fields[11]) + int(fields[12])          # utime + stime
        if pid == root:
            ticks += int(fields[13]) + int(fields[14])     # + cutime + cstime
        found[pid] = (_comm(f'/proc/{pid}/comm'), ticks)
    return found


def thread_ticks(pid):
    """Return {tid: (thread name, CPU ticks)} of one process."""
    found = {}
    try:
        tids = os.listdir(f'/proc/{pid}/task')
    except OSError:
        return found
    for tid in tids:
        fields = _stat_fields(f'/proc/{pid}/task/{tid}/stat')
        if fields is not None:
            found[int(tid)] = (_comm(f'/proc/{pid}/task/{tid}/comm'),
                               int(fields[11]) + int(fields[12]))
    return found


def _percent(ticks, seconds):
    return 100.0 * ticks / CLK_TCK / seconds


def _delta(before, after, seconds):
    """Return [(name, pid, % of a core)] of what ran between two samples, busiest first."""
    rows = [(name, pid, _percent(ticks - before.get(pid, (name, 0))[1], seconds))
            for pid, (name, ticks) in after.items()]
    return sorted(rows, key=lambda r: -r[2])


def wait_log(path, texts, proc, timeout):
    """Return the log at ``path`` once it holds every one of ``texts``; BenchError if not."""
    end = time.monotonic() + timeout
    while True:
        with open(path, errors='replace') as f:
            log = f.read()
        if all(t in log for t in texts):
            return log
        last = (log.strip().splitlines() or ['(empty)'])[-1]
        if proc.poll() is not None:
            raise BenchError(f'the process exited ({proc.returncode}) before writing '
                             f'{texts!r}; its last line: {last}')
        if time.monotonic() > end:
            raise BenchError(f'{texts!r} not written within {timeout:.0f} s; last line: '
                             f'{last}')
        time.sleep(0.1)


def measure_idle(domain, table, settle=20.0, window=60.0, timeout=300.0, params=()):
    """Return the idle CPU of one private node (``table``: contingency table on/off)."""
    workdir = tempfile.mkdtemp(prefix='namo_idle_')
    log_path = os.path.join(workdir, 'node.log')
    ros_args = node_ros_args(workdir, params=[f'contingency_table:={str(table).lower()}',
                                              *params])
    proc, log = start_logged(node_command(), ros_args, domain, log_path)
    try:
        wait_log(log_path, [NODE_READY] + ([TABLE_BUILT] if table else []), proc, timeout)
        time.sleep(settle)
        began, before = time.monotonic(), tree_ticks(proc.pid)
        threads_before = thread_ticks(proc.pid)
        time.sleep(window)
        after, threads_after = tree_ticks(proc.pid), thread_ticks(proc.pid)
        seconds = time.monotonic() - began
    finally:
        code, _ = _stop(proc, signal.SIGINT)
        read_log(log)
        shutil.rmtree(workdir, ignore_errors=True)
    total = sum(t for _, t in after.values()) - sum(t for _, t in before.values())
    return {'contingency_table': table, 'window_sec': round(seconds, 1), 'settle_sec': settle,
            'cpu_percent': round(_percent(total, seconds), 3),
            'processes': [{'name': n, 'pid': p, 'cpu_percent': round(c, 3)}
                          for n, p, c in _delta(before, after, seconds)],
            'threads': [{'name': n, 'tid': t, 'cpu_percent': round(c, 3)}
                        for n, t, c in _delta(threads_before, threads_after, seconds)[:8]],
            'exit_code': code}


def _stop(proc, sig, grace=STOP_GRACE_SEC):
    """Send ``sig``; return (exit code, seconds to exit), or (None, grace) if killed."""
    began = time.monotonic()
    proc.send_signal(sig)
    try:
        code = proc.wait(timeout=grace)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        return None, grace
    return code, time.monotonic() - began


def stop_trials(name, count, domain, timeout=120.0, seed=0):
    """Start ``name`` (recovery_node or namo_sim) ``count`` times; SIGTERM each one."""
    rng = random.Random(seed)
    codes, times = [], []
    for _ in range(count):
        workdir = tempfile.mkdtemp(prefix='namo_stop_')
        log_path = os.path.join(workdir, 'node.log')
        if name == 'recovery_node':
            command, ros_args, ready = node_command(), node_ros_args(workdir), NODE_READY
        else:
            command = executable_command('namo_sim', 'namo_fault_recovery.ros.sim_node')
            ros_args, ready = [], SIM_READY
        proc, log = start_logged(command, ros_args, domain, log_path)
        try:
            wait_log(log_path, [ready], proc, timeout)
            time.sleep(rng.uniform(0.0, 2.0))
        finally:
            code, seconds = _stop(proc, signal.SIGTERM)
            read_log(log)
            shutil.rmtree(workdir, ignore_errors=True)
        codes.append(code)
        times.append(seconds)
    clean = sum(1 for c in codes if c == 0)
    return {'node': name, 'stops': count, 'clean': clean, 'codes': codes,
            'slowest_sec': round(max(times), 3) if times else None}


def run_idle(out, domain, tables=(False, True), settle=20.0, window=60.0, stops=0,
             params=()):
    """Measure and print the idle CPU for each of ``tables``, then ``stops`` clean stops."""
    report = {'idle': [], 'stops': []}
    for table in tables:
        found = measure_idle(domain, table, settle, window, params=params)
        report['idle'].append(found)
        write_idle(out, found)
    for name in ('recovery_node', 'namo_sim') if stops else ():
        found = stop_trials(name, stops, domain)
        report['stops'].append(found)
        out.write(f'{name}: {found["clean"]}/{found["stops"]} SIGTERMs exited 0 within '
                  f'{STOP_GRACE_SEC:g} s (slowest {found["slowest_sec"]} s)\n')
        out.flush()
    return report


def write_idle(out, found):
    """Print one idle measurement: the total, each process, the busiest threads."""
    table = 'on' if found['contingency_table'] else 'off'
    out.write(f'recovery_node idle, contingency_table {table}: {found["cpu_percent"]:.2f} % '
              f'of one core (process tree, {found["window_sec"]:g} s after '
              f'{found["settle_sec"]:g} s settled; exit code {found["exit_code"]})\n')
    for row in found['processes']:
        out.write(f'  process {row["name"]:<18} {row["cpu_percent"]:6.3f} %\n')
    for row in found['threads']:
        if row['cpu_percent'] > 0:
            out.write(f'  thread  {row["name"]:<18} {row["cpu_percent"]:6.3f} %\n')
    out.flush()
