"""
``recovery_node``: the ROS 2 node that reconfigures Namo's gesture library after faults.

This module is the executable's entry point and stays light: it installs the signal
handlers first, so that SIGINT or SIGTERM at any moment of start-up (even while numpy,
scipy and rclpy are still being imported) ends the process cleanly with exit code 0,
starts the engine's child process (it imports the engine meanwhile; the node hands it
its files once its parameters are read), then imports the node (:mod:`.node`), spins
it, and shuts everything down.  The contract
(topics, services, QoS, behaviour) is documented in ``msg_docs/``.
"""

from pathlib import Path
import signal
import sys

from ..errors import EXIT_CONFIG

NODE_NAME = 'recovery_node'
_SIGNALS = []
_BEFORE_ROS = [True]


def _on_signal(signum, frame):
    """Before rclpy runs, a signal ends start-up at once; after, rclpy shuts ROS down."""
    _SIGNALS.append(signum)
    if _BEFORE_ROS[0]:
        raise SystemExit(0)
    if signum == signal.SIGINT and _SIGNALS.count(signal.SIGINT) > 1:
        raise KeyboardInterrupt


def _one_line(exc):
    return ' '.join(str(exc).split())


def _params_file_problem(path):
    """Return why a --params-file cannot be used, or None (rcl parses it for real)."""
    try:
        text = Path(path).read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError) as exc:
        return f'cannot read parameter file {path}: {exc}'
    import yaml
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' at line {mark.line + 1}' if mark is not None else ''
        return (f'parameter file {path} is not valid YAML{where}: '
                f'{getattr(exc, "problem", None) or exc}')

    def has_parameters(node):
        return isinstance(node, dict) and node and (
            isinstance(node.get('ros__parameters'), dict)
            or all(has_parameters(v) for v in node.values()))

    if not has_parameters(doc):
        return (f"parameter file {path}: expected '<node name or /**>: ros__parameters: "
                f"{{name: value}}' mappings")
    return None


def _check_params_files(argv):
    """Return the first problem with a --params-file of ``argv``, or None."""
    argv = list(argv)
    for i, token in enumerate(argv[:-1]):
        if token == '--params-file':
            problem = _params_file_problem(argv[i + 1])
            if problem:
                return problem
    return None


def swallowed_stop_hook(signals, default):
    """
    Return a ``sys.unraisablehook`` that drops what a start-up signal leaves behind.

    A signal's SystemExit that lands in code whose exceptions Python ignores (a weakref
    callback such as importlib's module-lock one) is printed as "Exception ignored"
    with a traceback, and start-up goes on; its next check of ``signals`` then ends it
    with exit 0.  One that lands inside a constructor leaves a half-built object, whose
    finaliser then fails on the attributes it never got (rclpy's executor and its
    signal guard condition: ``Executor.__del__`` without ``_sigint_gc``, seen once in a
    fresh-clone CI with SIGTERM 0.7 s into start-up): after a start-up signal a
    finaliser's error is dropped too.  Anything else goes to ``default``.
    """
    def hook(info):
        finaliser = getattr(info.object, '__name__', None) == '__del__'
        if signals and (isinstance(info.exc_value, SystemExit) or finaliser):
            return
        default(info)
    return hook


def main(args=None):
    """Run the node until Ctrl-C or SIGTERM; return the exit code."""
    sys.unraisablehook = swallowed_stop_hook(_SIGNALS, sys.__unraisablehook__)
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, _on_signal)
    try:
        return _run(args)
    except BaseException as exc:
        if _SIGNALS and cut_short_by_signal(exc):
            return 0                 # stopped during start-up: a clean exit
        raise exc


def cut_short_by_signal(exc):
    """
    Return True if ``exc`` is, or was caused by, the SystemExit of a start-up signal.

    An extension module being imported when the signal came turns it into an error of
    its own (pybind11's ``ImportError: initialization failed``, caused by it).
    """
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, SystemExit):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def _run(args):
    problem = _check_params_files(sys.argv if args is None else args)
    if problem:
        sys.stderr.write(f'{NODE_NAME}: error: {_one_line(problem)}\n')
        return EXIT_CONFIG
    # The engine child imports the engine while this process imports the node (both
    # take about a second): it gets its files once the parameters are read.
    from ..runtime.engine_process import EngineProcess
    engine = EngineProcess.early()
    try:
        return _run_node(args, engine)
    finally:
        engine.stop()        # a refused configuration (else the node stopped it already)


def _run_node(args, engine):
    from .node import RecoveryNode
    from .parameters import StartupError
    from .spin import run_node
    # A /joint_states stream keeps the executor's threads busy with short Python work;
    # the default 5 ms interpreter-lock switch interval then makes the dispatcher and
    # intake threads wait in a convoy (measured: runs starting up to 1.9 s late at
    # 500 Hz).  A shorter interval hands the lock over sooner.
    sys.setswitchinterval(0.0005)
    # From here rclpy's handlers shut ROS down (spin then ends) and chain to ours, which
    # no longer raises: an exception at an arbitrary point could leave a thread behind.
    _BEFORE_ROS[0] = False
    return run_node(NODE_NAME, lambda: RecoveryNode(engine=engine), args,
                    config_errors=(StartupError,), interrupted=lambda: bool(_SIGNALS))


if __name__ == '__main__':
    sys.exit(main())
