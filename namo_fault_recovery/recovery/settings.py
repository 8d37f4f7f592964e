"""
Every setting of the engine and of the node, declared once; :class:`RecoverySettings`.

A :class:`Setting` gives a name, a type, a default, a range or choices, a unit, one line
of doc and the flags its users need: ``scope`` (``engine``: a field of
:class:`RecoverySettings`, or of its ``weights``; ``node``: the node's own), ``rerun``
(a change makes the node reconfigure the library), ``read_only`` (fixed at start-up) and
``cli`` (an option of ``solve`` and ``precompute``).  :data:`SETTINGS`, in the node's
parameter order, is the one table that everything else comes from:

- :class:`RecoverySettings`, whose fields are declared with :func:`setting` below, and
  its validation, :func:`check` (one-line reasons naming the key, the value and what
  was expected), which the node's on-set callback and the command line also use;
- the ROS parameters and their descriptors (``ros/parameters.py``);
- the ``solve`` / ``precompute`` options (``cli/common.py``);
- ``config/recovery_node.yaml`` and the parameter tables of the README and
  ``msg_docs/interfaces.md``, written by ``namo-recovery settings --write`` (a test
  checks they are up to date).

Adding a setting: declare it here (a field of :class:`RecoverySettings` for the engine,
a row of :data:`SETTINGS` for the node), use it where it acts, and run
``namo-recovery settings --write``.  Free of ROS.
"""

from dataclasses import asdict, dataclass, field, fields, replace
import math

from .keyframes import BIMANUAL_MODES
from .locks import LOCK_STRATEGIES
from .motion import DEFAULT_CONTINUITY, DEFAULT_DISTORTION_MM, METHODS
from ..errors import shorten
from ..model.robot import ARMS
from ..model.weights import COMPONENTS, ScoreWeights
from ..optimize import ALGORITHMS, PRESETS

ENGINE = 'engine'
NODE = 'node'
DEFAULT_STATE_DIR = '~/.ros/namo_fault_recovery'
BOUNDS = {'> 0': lambda v: v > 0, '>= 0': lambda v: v >= 0}
TYPE_NAMES = {str: 'a string', float: 'a floating-point number', int: 'an integer',
              bool: 'true or false'}


@dataclass(frozen=True)
class Setting:
    """
    One setting: what it is, its default and bounds, and how each user treats it.

    ``limits`` (low, high) are the node parameter's range (its descriptor); ``bound``
    (``'> 0'``, ``'>= 0'`` or None) is what every user checks a number against.
    ``aliases``, ``cli_help`` and ``metavar`` shape the command-line option ``--name``
    (with dashes); for a flag an alias ``--no-...`` is the negative form.
    """

    name: str
    value_type: type
    default: object
    doc: str
    unit: str = ''
    limits: tuple = None
    bound: str = None
    choices: tuple = None
    scope: str = NODE
    rerun: bool = False
    read_only: bool = False
    cli: bool = False
    aliases: tuple = ()
    cli_help: str = None
    metavar: str = None

    @property
    def option(self) -> str:
        """Return the command-line option: ``--vq-distortion-mm`` for ``vq_distortion_mm``."""
        return '--' + self.name.replace('_', '-')


def setting(default: object, doc: str, **spec) -> object:
    """Declare a :class:`RecoverySettings` field: its default and its :class:`Setting`."""
    spec.setdefault('rerun', True)
    spec.setdefault('cli', True)
    return field(default=default, metadata={'setting': dict(spec, doc=doc)})


@dataclass(frozen=True)
class RecoverySettings:
    """
    Every setting that changes the adapted library, named as the node's parameters.

    The defaults are the node's (``config/recovery_node.yaml``).  ``weights`` is a
    :class:`~namo_fault_recovery.objective.score.ScoreWeights` (None: the paper's); the
    node's ``weights.*`` parameters are its fields.  Each field is declared with its
    :class:`Setting` (see :data:`SETTINGS`) and checked by :func:`check`.
    """

    deadline_sec: float = setting(
        1.0, "hard budget for one reconfiguration of the whole library (the paper's 1 s)",
        unit='s', limits=(0.01, 60.0), bound='> 0', aliases=('--deadline',),
        metavar='SEC',
        cli_help='budget for the whole library in s (default %(default)g; 0: no deadline)')
    lock_strategy: str = setting(
        'average', 'lock angle of a joint reported without a position: the mean over the '
        "gestures of its arm (the paper's), where /joint_states last saw it (the mean if "
        'never seen), or the best for the whole library', choices=LOCK_STRATEGIES)
    optimizer: str = setting(
        'abc', "optimiser: abc, the paper's artificial bee colony; the others for "
        'comparison', choices=tuple(ALGORITHMS), aliases=('--algorithm',))
    optimizer_preset: str = setting(
        'default', 'optimiser settings: default (product tuning) or paper (Table 3)',
        choices=PRESETS, aliases=('--preset',),
        cli_help="'default' (our tuned ABC) or 'paper' (the paper's Table 3)")
    bimanual: str = setting(
        'auto', 'two-handed gestures: let the healthy arm move too (stage 2); auto = when '
        'the faulted arm alone scores poorly', choices=BIMANUAL_MODES,
        cli_help="stage 2 for two-handed gestures: the healthy arm moves too ('auto': when "
                 'stage 1 scores above the threshold)')
    collision_check: bool = setting(
        True, 'keep the arms and the torso apart (capsule model); the poses that still '
        'collide are reported (<g>.collides on /diagnostics, COLLIDES in the summary)',
        aliases=('--no-collision',),
        cli_help='keep arms and torso apart and report what still collides')
    expand_shared: bool = setting(
        False, "staged DOF expansion into the joints shared by both arms (the profile's "
        'shared, a torso): a gesture whose fingertip stays over 5 mm off with the arms '
        'alone is searched again with the torso leaned, one lean per gesture (its shared '
        'joints in the trajectory, for a torso controller); off by default: it costs time '
        'at the deadline and a guest sees the torso move', cli_help='lean the torso '
        '(shared joints) for gestures the arms alone cannot reach')
    tool_length_mm: float = setting(
        0.0, "a tool in the hand of tool_arm lengthens it by this much (the second paper's "
        '50 and 100 mm): a structure change; setting it re-adapts the library even with no '
        'failed joint, and setting 0 restores the reference', unit='mm',
        limits=(0.0, 300.0), bound='>= 0', metavar='MM', aliases=('--tool',),
        cli_help='a tool lengthening the hand of --tool-arm (mm)')
    tool_arm: str = setting('right', 'the arm whose hand holds the tool', choices=ARMS)
    trajectory_method: str = setting(
        'auto', 'motions: kriging = VQ typical points + Kriging (the second paper); '
        'per_point = every point in order, warm-started, with a continuity penalty; auto = '
        'Kriging, then the whole trajectory (every point at once, batched analytic '
        'gradients, a smoothness term) until the deadline', choices=METHODS,
        aliases=('--method',))
    vq_distortion_mm: float = setting(
        DEFAULT_DISTORTION_MM, 'quantisation distortion threshold (mm of fingertip) that '
        "sets the number of typical points of a dense motion (the paper's 60 mm)",
        unit='mm', limits=(1.0, 1000.0), bound='> 0', metavar='MM',
        cli_help='typical-point threshold (mm of fingertip)')
    continuity_weight: float = setting(
        DEFAULT_CONTINUITY, 'per-point adaptation: penalty per deg^2 of joint jump away from '
        'the previous point plus the designed step', unit='per deg^2', limits=(0.0, 100.0),
        bound='>= 0', metavar='W', cli_help='per-point jump penalty (per deg^2)')
    weights: ScoreWeights = field(default_factory=ScoreWeights)

    def __post_init__(self) -> None:
        for name in ENGINE_FIELDS:
            reason = check(name, getattr(self, name))
            if reason:
                raise ValueError(reason)
        if self.weights is not None and not isinstance(self.weights, ScoreWeights):
            raise ValueError(f'weights: expected a ScoreWeights or None, got '
                             f'{shorten(repr(self.weights))}')

    def with_changes(self, **changes) -> 'RecoverySettings':
        """Return a copy with some settings changed (validated again)."""
        return replace(self, **changes)

    def public(self) -> dict:
        """Return the settings as a JSON-ready dict (what a result records)."""
        return asdict(self)


def _engine_rows():
    """Return the :class:`Setting` of every declared :class:`RecoverySettings` field."""
    rows = []
    for f in fields(RecoverySettings):
        if 'setting' in f.metadata:
            if not isinstance(f.default, f.type) or isinstance(f.default, bool) != (
                    f.type is bool):
                raise TypeError(f'RecoverySettings.{f.name}: default {f.default!r} is not '
                                f'a {f.type.__name__}')
            rows.append(Setting(f.name, f.type, f.default, scope=ENGINE, **f.metadata[
                'setting']))
    return rows


def _weight_rows():
    """Return the ``weights.*`` settings: the fields of :class:`ScoreWeights`."""
    default = ScoreWeights()
    rows = [Setting(f'weights.{c}', float, getattr(default, c),
                    f'score weight of the {c} component; one of the first four > 0',
                    limits=(0.0, 1000.0), bound='>= 0', scope=ENGINE, rerun=True)
            for c in COMPONENTS]
    rows.append(Setting('weights.normalise', bool, default.normalise,
                        "scale the weights a gesture uses so they sum to 1 (the paper's "
                        'equal weights)', scope=ENGINE, rerun=True))
    return rows


def _rows(engine_rows, weight_rows):
    """Return the table: the node's own settings around the engine's, in parameter order."""
    return (
        Setting('robot_file', str, '', 'arm model YAML (DH, joint names, limits); empty = '
                'the packaged Namo model (unless robot_profile is given)', read_only=True),
        Setting('robot_profile', str, '', 'recovery profile YAML of any robot (arms, '
                'landmark links, recovery joints; config/robots/talos.yaml): the robot is '
                'built from it and its URDF instead of robot_file; empty = robot_file',
                read_only=True),
        Setting('robot_description', str, '', "the robot's URDF document (the XML text "
                'robot_state_publisher takes): it replaces the URDF that robot_profile names; '
                "empty = the profile's urdf, or if it names none the robot_description topic "
                '(transient local, waited for)', read_only=True),
        Setting('gesture_file', str, '', 'reference gesture library YAML; empty = the '
                "packaged library (Namo's 4 paper gestures as motions); "
                'config/demo_motions.yaml adds the dense 100-point circle; with '
                "robot_profile, give that robot's (config/robots/talos_gestures.yaml)",
                read_only=True),
        *engine_rows,
        Setting('seed', int, -1, 'random seed for reproducible runs; -1 draws one per run '
                '(reported on /diagnostics)',
                limits=(-1, 2 ** 31 - 1), rerun=True),
        *weight_rows,
        Setting('state_dir', str, DEFAULT_STATE_DIR, 'directory where the fault set, the '
                'last library and the contingency table persist (~ and $VARS expanded)',
                read_only=True),
        Setting('marker_frame_id', str, 'base_link', 'frame of the /gesture_markers '
                'skeletons (the torso centre)'),
        Setting('marker_spacing', float, 0.8, 'distance between the gestures shown on '
                '/gesture_markers', unit='m', limits=(0.0, 10.0)),
        Setting('refine_budget_sec', float, 10.0, 'after a deadline result the node keeps '
                'searching (further seeds) in the background for this long and publishes '
                'each library better by more than 0.1% as a new version (library_origin: '
                'refined); 0 = off; a new fault or call cancels it', unit='s',
                limits=(0.0, 600.0)),
        Setting('contingency_table', bool, True, 'precompute, in a nice 19 process stopped '
                'while a live run computes, the library of every single fault at the lock '
                "strategy's angle (and, once faults are active, of every further single "
                'fault on top of them); kept in state_dir/contingency_table.json under a '
                'fingerprint of the robot, the library and every setting that changes the '
                'result; a fault found there is published at once (library_origin: table)'),
        Setting('contingency_file', str, '', "a table built offline ('namo-recovery "
                "precompute --jobs N --out FILE'), merged at start if its fingerprint (robot, "
                'library, settings) matches; otherwise the reason is logged', read_only=True),
        Setting('profile_file', str, '', 'recovery profile (URDF + profile YAML) of the '
                "nominal chains the gesture player's measured corrections are fitted on (its "
                'profile_file); empty = robot_profile (with robot_description), else the '
                'packaged Namo profile', read_only=True),
        Setting('explored_topic', str, 'gesture_player/explored_motions', 'the gesture '
                "player's latched explored motions: with its correction on "
                '/structure_correction each becomes a library version (library_origin: '
                "explored) and the arm's corrected model for later faults; empty = off",
                read_only=True),
        *_process_rows(),
    )


def _process_rows():
    """Return the settings of the node's process: its diagnostics, engine start, priority."""
    return (
        Setting('diagnostics_period_sec', float, 1.0, 'period of /diagnostics (also '
                'published on every change)', unit='s', limits=(0.1, 60.0), read_only=True),
        Setting('engine_start_timeout_sec', float, 60.0, 'the engine process must be '
                'loaded and warmed up within this long, at start and after a restart, or the '
                'node refuses to start (the run fails)', unit='s', limits=(1.0, 600.0),
                read_only=True),
        Setting('thread_priority', int, 0, "SCHED_FIFO real-time priority of the node's own "
                'threads (executor, /joint_states listener, fault intake, middleware), set '
                "once the node is ready, as ros2_control's controller manager sets its "
                "loop's; the engine and table processes stay under the normal scheduler; "
                'needs the rtprio limit (/etc/security/limits.conf): if refused, the node '
                'logs why and runs under the normal scheduler; 0 = off',
                limits=(0, 99), read_only=True),
        Setting('engine_nice', int, -5, 'nice value at which the engine process computes '
                "a fault's deadline run, so that a busy robot's best-effort work delays a "
                'recovery less (-5: three times the CPU share of nice 0; still the normal '
                'scheduler); its warm-up and the background refinements compute at its own '
                'nice; below that needs CAP_SYS_NICE or the nice limit '
                '(/etc/security/limits.conf): if refused, the node logs why and the runs '
                'compute at its own; 0 = the share of nice 0', limits=(-20, 19), read_only=True),
    )


SETTINGS = _rows(_engine_rows(), _weight_rows())
BY_NAME = {s.name: s for s in SETTINGS}
# The RecoverySettings fields declared as settings (all but ``weights``), in order.
ENGINE_FIELDS = tuple(s.name for s in SETTINGS if s.scope == ENGINE and '.' not in s.name)
WEIGHT_PARAMS = tuple(s.name for s in SETTINGS if s.name.startswith('weights.'))


def check(name: str, value: object, current: dict = None) -> str | None:
    """
    Return None if ``value`` is acceptable for setting ``name``, else the one-line reason.

    The reason names the key, the value (bounded) and what was expected.  ``current``
    maps the other settings to their values, for the checks that involve several (the
    score weights).  A name that is not declared is not checked.
    """
    s = BY_NAME.get(name)
    if s is None:
        return None
    got = f'got {shorten(repr(value))}'
    if s.choices is not None:
        if value not in s.choices:
            return (f'{name}: unknown value {shorten(repr(value))}; expected one of '
                    f'{", ".join(s.choices)}')
    elif s.value_type is bool:
        if not isinstance(value, bool):
            return f'{name}: expected true or false, {got}'
    elif s.value_type is float:
        if (isinstance(value, bool) or not isinstance(value, (int, float))
                or not math.isfinite(value)
                or (s.bound is not None and not BOUNDS[s.bound](value))):
            bound = f' {s.bound}' if s.bound else ''
            return f'{name}: expected a finite number{bound}, {got}'
    elif not isinstance(value, s.value_type) or isinstance(value, bool):
        return f'{name}: expected {TYPE_NAMES[s.value_type]}, {got}'
    if name in WEIGHT_PARAMS and current is not None and all(
            p in current for p in WEIGHT_PARAMS if p != 'weights.normalise'):
        try:
            weights_from(dict(current, **{name: value}))
        except ValueError as exc:
            return str(exc)
    return None


def weights_from(values: dict) -> ScoreWeights:
    """Return the :class:`ScoreWeights` of the ``weights.*`` entries of ``values``."""
    return ScoreWeights.from_mapping({p.split('.', 1)[1]: values[p] for p in WEIGHT_PARAMS
                                      if p in values})


def settings_from(values: dict) -> RecoverySettings:
    """Return the :class:`RecoverySettings` of a ``{setting: value}`` mapping (every one)."""
    return RecoverySettings(weights=weights_from(values),
                            **{n: BY_NAME[n].value_type(values[n]) for n in ENGINE_FIELDS})
