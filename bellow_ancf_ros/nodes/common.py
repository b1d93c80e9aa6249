"""Message-free helpers shared by the ROS 2 nodes (no rclpy import).

Everything here works on plain numbers and numpy arrays so that it can be
tested without ROS:

* pressure units and the ``Float64MultiArray`` layout label
  (:func:`pressure_label`, :func:`to_unit`, :func:`from_unit`);
* the pressure safety gate :func:`safe_pressures`, through which every
  pressure a node publishes passes (refuses NaN, inf, a wrong count and
  anything outside ``[p_min, p_max]``);
* validation of incoming data: :func:`validate_target` (target pose),
  :func:`validate_pressure_input` (pressure arrays for the forward node);
* quaternion conversions (ROS order ``x, y, z, w``):
  :func:`quaternion_to_rotation`, :func:`z_axis_from_quaternion`,
  :func:`quaternion_from_rotation`, :func:`quaternion_from_z_axis`;
* :class:`LatestWorker`: a worker thread that always processes the newest
  item only (older ones are overwritten, so memory stays bounded) at a bounded
  rate;
* :class:`SolveStats`: solve-time statistics and the age of the last solve
  for the status heartbeat;
* the texts that tell a user how to get out of a refused or failed state
  (:func:`configure_time_refusal`, :func:`configure_failed_hint`).

All pressures are gauge pressures (relative to atmosphere).  Inside the
package they are in Pa (REP-103 SI units); on a topic the unit is ``Pa`` by
default or ``kPa`` when a node's ``pressure_unit`` parameter says so.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

__all__ = [
    'PAYLOAD_MAX_KG',
    'PRESSURE_UNITS',
    'InputError',
    'LatestWorker',
    'SolveStats',
    'UnsafePressureError',
    'angle_between',
    'check_unit',
    'configure_failed_hint',
    'configure_time_refusal',
    'from_unit',
    'parameter_problem',
    'pressure_label',
    'quaternion_from_rotation',
    'quaternion_from_z_axis',
    'quaternion_to_rotation',
    'safe_pressures',
    'to_unit',
    'unit_from_label',
    'validate_payload',
    'validate_pressure_input',
    'validate_target',
    'vent_pressures',
    'z_axis_from_quaternion',
]

#: Pressure units accepted by the ``pressure_unit`` parameters: factor to Pa.
PRESSURE_UNITS = {'Pa': 1.0, 'kPa': 1e3}

#: Largest payload the nodes accept [kg] (the paper uses 0-100 g).
PAYLOAD_MAX_KG = 1.0

#: Smallest quaternion norm that is still normalised (anything below is refused).
QUATERNION_MIN_NORM = 1e-6

#: Relative tolerance on the pressure limits (round-off of unit conversions);
#: values within it are clipped onto the limit, values beyond it refused.
LIMIT_RTOL = 1e-9


class InputError(ValueError):
    """Incoming data (target pose, pressure array) that a node refuses."""


class UnsafePressureError(ValueError):
    """A pressure vector that must never be published."""


# ----------------------------------------------------------------- units
def check_unit(unit: str) -> str:
    """Return ``unit`` if it is a known pressure unit, else raise ``ValueError``."""
    if unit not in PRESSURE_UNITS:
        raise ValueError(f"pressure unit must be one of {sorted(PRESSURE_UNITS)}, got {unit!r}")
    return unit


def pressure_label(unit: str = 'Pa') -> str:
    """``layout.dim[0].label`` of a pressure array in ``unit``: ``actuator_pressure_gauge_pa``."""
    return 'actuator_pressure_gauge_' + check_unit(unit).lower()


def unit_from_label(label: str) -> str | None:
    """The unit a layout label names (``..._pa`` / ``..._kpa``), or None if it names none."""
    lab = (label or '').strip().lower()
    if lab.endswith('_kpa') or lab == 'kpa':
        return 'kPa'
    if lab.endswith('_pa') or lab == 'pa':
        return 'Pa'
    return None


def to_unit(pressures_pa: Any, unit: str) -> np.ndarray:
    """Pa -> ``unit``."""
    return np.asarray(pressures_pa, dtype=float) / PRESSURE_UNITS[check_unit(unit)]


def from_unit(values: Any, unit: str) -> np.ndarray:
    """``unit`` -> Pa."""
    return np.asarray(values, dtype=float) * PRESSURE_UNITS[check_unit(unit)]


# ---------------------------------------------------------------- safety
def safe_pressures(p: Any, p_min: float, p_max: float, n: int | None = None) -> np.ndarray:
    """The pressure safety gate: ``p`` [Pa] as a float array, or raise.

    Raises :class:`UnsafePressureError` if ``p`` is empty, has the wrong count
    (when ``n`` is given), holds NaN or inf, or lies outside
    ``[p_min, p_max]`` by more than a round-off tolerance
    (``LIMIT_RTOL * (p_max - p_min)``).  Values within that tolerance are
    clipped onto the limit, so the result always satisfies
    ``p_min <= p <= p_max`` exactly.
    """
    if not (math.isfinite(p_min) and math.isfinite(p_max) and p_min <= p_max):
        raise UnsafePressureError(f'invalid pressure limits [{p_min}, {p_max}] Pa')
    try:
        arr = np.array(p, dtype=float).ravel()
    except (TypeError, ValueError) as exc:
        raise UnsafePressureError(f'pressures are not numbers: {exc}') from None
    if arr.size == 0:
        raise UnsafePressureError('empty pressure vector')
    if n is not None and arr.size != n:
        raise UnsafePressureError(f'expected {n} pressures (one per actuator), got {arr.size}')
    if not np.all(np.isfinite(arr)):
        bad = int(np.flatnonzero(~np.isfinite(arr))[0])
        raise UnsafePressureError(f'pressure {bad + 1} is {arr[bad]} (not a finite number)')
    tol = LIMIT_RTOL * max(p_max - p_min, 1.0)
    out = (arr < p_min - tol) | (arr > p_max + tol)
    if np.any(out):
        i = int(np.flatnonzero(out)[0])
        raise UnsafePressureError(
            f'pressure {i + 1} = {arr[i] / 1e3:.6g} kPa is outside the limits '
            f'[{p_min / 1e3:g}, {p_max / 1e3:g}] kPa')
    return np.clip(arr, p_min, p_max)


def vent_pressures(n: int, p_min: float, p_max: float) -> np.ndarray:
    """Vent command: 0 Pa gauge on every actuator (clipped into the limits)."""
    return safe_pressures(np.clip(np.zeros(int(n)), p_min, p_max), p_min, p_max, n)


def validate_pressure_input(values: Sequence[float], unit: str, n: int, p_min: float,
                            p_max: float, label: str | None = None) -> np.ndarray:
    """Check an incoming pressure array (forward node) and return it in Pa.

    ``label`` is ``layout.dim[0].label`` when the message has one: if it names
    a unit (``..._pa`` / ``..._kpa``) that differs from ``unit``, the array is
    refused rather than misread by a factor of 1000.
    """
    named = unit_from_label(label) if label else None
    if named is not None and named != unit:
        raise InputError(f'array is labelled {label!r} ({named}) but pressure_unit is {unit}')
    try:
        return safe_pressures(from_unit(np.asarray(values, dtype=float), unit), p_min, p_max, n)
    except UnsafePressureError as exc:
        raise InputError(str(exc)) from None


def validate_payload(value: Any, maximum: float = PAYLOAD_MAX_KG) -> float:
    """A payload [kg] in ``[0, maximum]`` as a float, else ``ValueError`` with the reason."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f'payload_kg must be a number, got {type(value).__name__}')
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f'payload_kg must be finite, got {v}')
    if v < 0.0:
        raise ValueError(f'payload_kg must not be negative, got {v} kg')
    if v > maximum:
        raise ValueError(f'payload_kg {v} kg exceeds the maximum of {maximum} kg')
    return v


def parameter_problem(name: str, value: Any) -> str:
    """Why a node parameter value is refused ('' if it is fine).

    Shared by the nodes' set-parameters callbacks: ``payload_kg``,
    ``pressure_unit``, ``max_rate_hz``, ``base_frame``, ``robot_config``
    (must load); other names are not checked here.
    """
    try:
        if name == 'payload_kg':
            validate_payload(value)
        elif name == 'pressure_unit':
            check_unit(value)
        elif name == 'max_rate_hz':
            if not (isinstance(value, float) and math.isfinite(value) and value > 0):
                return f'max_rate_hz must be a positive number, got {value}'
        elif name == 'base_frame':
            if not isinstance(value, str) or not value:
                return 'base_frame must be a non-empty string'
        elif name == 'robot_config':
            from ..core import load_robot
            load_robot(value)  # takes effect on the next configure
    except ValueError as exc:  # ConfigError is a ValueError
        return str(exc)
    return ''


# ------------------------------------------------------------ quaternions
def _unit_quaternion(q: Sequence[float]) -> np.ndarray:
    arr = np.array(q, dtype=float).ravel()
    if arr.size != 4:
        raise InputError(f'a quaternion has 4 components, got {arr.size}')
    if not np.all(np.isfinite(arr)):
        raise InputError('quaternion has NaN or inf components')
    nrm = float(np.linalg.norm(arr))
    if not math.isfinite(nrm) or nrm < QUATERNION_MIN_NORM:
        raise InputError(f'quaternion cannot be normalised (norm {nrm:.3g})')
    return arr / nrm


def quaternion_to_rotation(q: Sequence[float]) -> np.ndarray:
    """Rotation matrix (columns = rotated x, y, z axes) of a quaternion ``(x, y, z, w)``.

    The quaternion is normalised; zero, NaN or inf ones raise :class:`InputError`.
    """
    x, y, z, w = _unit_quaternion(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def z_axis_from_quaternion(q: Sequence[float]) -> np.ndarray:
    """The local z-axis (third column of the rotation) of ``(x, y, z, w)``, unit length."""
    x, y, z, w = _unit_quaternion(q)
    v = np.array([2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y)])
    return v / np.linalg.norm(v)


def quaternion_from_rotation(R: Any) -> np.ndarray:
    """Quaternion ``(x, y, z, w)`` (``w >= 0``) of a rotation matrix (Shepperd's method)."""
    m = np.asarray(R, dtype=float).reshape(3, 3)
    if not np.all(np.isfinite(m)):
        raise ValueError('rotation matrix has NaN or inf entries')
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(max(1.0 + m[0, 0] - m[1, 1] - m[2, 2], 1e-300))
        q = [0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(max(1.0 + m[1, 1] - m[0, 0] - m[2, 2], 1e-300))
        q = [(m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
    else:
        s = 2.0 * math.sqrt(max(1.0 + m[2, 2] - m[0, 0] - m[1, 1], 1e-300))
        q = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


def quaternion_from_z_axis(z_axis: Any) -> np.ndarray:
    """Quaternion ``(x, y, z, w)`` of the smallest rotation taking base ``z`` onto ``z_axis``."""
    v = np.asarray(z_axis, dtype=float).reshape(3)
    n = float(np.linalg.norm(v))
    if not math.isfinite(n) or n < 1e-12:
        raise ValueError('z-axis must be a finite non-zero vector')
    v = v / n
    c = float(v[2])
    if c < -1.0 + 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0])  # half turn about x
    # rotation axis e_z x v, angle acos(c): q = (sin(a/2) axis, cos(a/2))
    w = math.sqrt(0.5 * (1.0 + c))
    s = 0.5 / w
    return np.array([-v[1] * s, v[0] * s, 0.0, w])


def angle_between(a: Any, b: Any) -> float:
    """Angle between two vectors [rad] (robust near 0 and pi)."""
    a = np.asarray(a, dtype=float).reshape(3)
    b = np.asarray(b, dtype=float).reshape(3)
    return float(math.atan2(np.linalg.norm(np.cross(a, b)), float(np.dot(a, b))))


# ---------------------------------------------------------------- targets
def validate_target(position: Sequence[float], quaternion: Sequence[float] | None,
                    frame_id: str, base_frame: str, use_orientation: bool):
    """Check a target pose; return ``(position (3,), z_axis (3,) or None)``.

    Raises :class:`InputError` naming the reason for a wrong frame, a
    non-finite position, or (when ``use_orientation``) a quaternion that is
    non-finite or cannot be normalised.  An empty ``frame_id`` is refused too:
    without tf2 the node cannot know what frame was meant.
    """
    if frame_id != base_frame:
        raise InputError(f"target frame {frame_id!r} is not the base frame {base_frame!r} "
                         '(no tf2 transform is done)')
    p = np.array(position, dtype=float).ravel()
    if p.size != 3 or not np.all(np.isfinite(p)):
        raise InputError(f'target position must be 3 finite numbers, got {p.tolist()}')
    z = z_axis_from_quaternion(quaternion) if use_orientation else None
    return p, z


# ------------------------------------------------------------ latest-only
class LatestWorker:
    """Process only the newest submitted item, in a worker thread, at a bounded rate.

    ``submit(item)`` stores ``item`` in a single slot (overwriting an item not
    yet processed, which counts as dropped) and wakes the worker.  The worker
    calls ``process(item)`` for the newest item, and starts two calls at least
    ``min_period()`` seconds apart.  Memory is one item, whatever the input rate.
    Exceptions from ``process`` are passed to ``on_error`` (default: ignored) and
    the worker keeps running.
    """

    def __init__(self, process: Callable[[Any], None],
                 min_period: Callable[[], float] = lambda: 0.0,
                 on_error: Callable[[BaseException], None] | None = None,
                 name: str = 'latest-worker') -> None:
        self._process = process
        self._min_period = min_period
        self._on_error = on_error
        self._cond = threading.Condition()
        self._item: Any = None
        self._has_item = False
        self._stop = False
        self._busy = False
        self._last_start = -math.inf
        self.submitted = 0
        self.dropped = 0
        self.processed = 0
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, item: Any) -> None:
        with self._cond:
            if self._has_item:
                self.dropped += 1
            self._item = item
            self._has_item = True
            self.submitted += 1
            self._cond.notify_all()

    def resubmit(self, item: Any) -> bool:
        """Queue ``item`` again unless a newer item is pending; return whether queued."""
        with self._cond:
            if self._has_item or self._stop:
                return False
            self._item = item
            self._has_item = True
            self._cond.notify_all()
            return True

    def clear(self) -> None:
        """Drop a pending item (not yet started)."""
        with self._cond:
            if self._has_item:
                self.dropped += 1
            self._item = None
            self._has_item = False

    @property
    def pending(self) -> bool:
        with self._cond:
            return self._has_item

    def idle(self) -> bool:
        """True when no item is pending and none is being processed."""
        with self._cond:
            return not self._has_item and not self._busy

    def wait_idle(self, timeout: float) -> bool:
        """Wait until :meth:`idle` (or ``timeout`` seconds); return whether idle."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._has_item or self._busy:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(min(left, 0.05))
            return True

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._has_item and not self._stop:
                    self._cond.wait()
                if self._stop:
                    return
                # bounded rate: wait until min_period after the last start;
                # newer items arriving meanwhile replace the pending one
                while not self._stop:
                    period = max(0.0, float(self._min_period()))
                    left = self._last_start + period - time.monotonic()
                    if left <= 0:
                        break
                    self._cond.wait(left)
                if self._stop:
                    return
                if not self._has_item:
                    continue
                item = self._item
                self._item = None
                self._has_item = False
                self._busy = True
                self._last_start = time.monotonic()
            try:
                self._process(item)
            except BaseException as exc:  # noqa: BLE001 - the worker must survive
                if self._on_error is not None:
                    try:
                        self._on_error(exc)
                    except Exception:  # noqa: BLE001
                        pass
            finally:
                with self._cond:
                    self._busy = False
                    self.processed += 1
                    self._cond.notify_all()

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the worker (a running ``process`` call is waited for up to ``timeout``)."""
        with self._cond:
            self._stop = True
            self._item = None
            self._has_item = False
            self._cond.notify_all()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout)


# ------------------------------------------------------------ statistics
class SolveStats:
    """Solve-time statistics over the last ``window`` solves, and the age of the last one.

    ``record(seconds, ok)`` after every solve; :meth:`summary` gives the count,
    the last/median/95th-percentile/maximum solve time over the window [s],
    the age of the last solve [s] (None before the first) and whether it
    succeeded.  Memory is bounded by ``window``.  Thread-safe.
    """

    def __init__(self, window: int = 1000, clock: Callable[[], float] = time.monotonic) -> None:
        self._times: deque = deque(maxlen=int(window))
        self._clock = clock
        self._lock = threading.Lock()
        self.count = 0
        self.failures = 0
        self._last_end: float | None = None
        self._last_ok: bool | None = None

    def record(self, seconds: float, ok: bool = True) -> None:
        """Record one solve that took ``seconds`` and ended now."""
        with self._lock:
            self._times.append(float(seconds))
            self.count += 1
            self.failures += 0 if ok else 1
            self._last_end = self._clock()
            self._last_ok = bool(ok)

    def times(self) -> list:
        """The solve times in the window [s], oldest first."""
        with self._lock:
            return list(self._times)

    def summary(self) -> dict:
        """Statistics as a dict (None where there is no solve yet).

        Keys: ``count``, ``failures``, ``window``, ``last_s``, ``median_s``,
        ``p95_s``, ``max_s``, ``last_solve_age_s``, ``last_ok``.
        """
        with self._lock:
            t = np.array(self._times, dtype=float)
            last_end, last_ok = self._last_end, self._last_ok
            count, failures = self.count, self.failures
        empty = t.size == 0
        return {
            'count': count,
            'failures': failures,
            'window': int(t.size),
            'last_s': None if empty else float(t[-1]),
            'median_s': None if empty else float(np.median(t)),
            'p95_s': None if empty else float(np.percentile(t, 95)),
            'max_s': None if empty else float(t.max()),
            'last_solve_age_s': None if last_end is None else self._clock() - last_end,
            'last_ok': last_ok,
        }


# ------------------------------------------------------- recovery texts
def configure_time_refusal(name: str, node_path: str, state: str, current: Any) -> str:
    """Why a parameter read on configure cannot change now, and the way out.

    ``node_path`` is the node's fully qualified name (``/inverse_kinetostatic_node``),
    ``state`` its lifecycle state (``active``, ``inactive``), ``current`` the
    value in use.
    """
    steps = []
    if state == 'active':
        steps.append(f'ros2 lifecycle set {node_path} deactivate')
    steps += [f'ros2 lifecycle set {node_path} cleanup',
              f'ros2 param set {node_path} {name} <new value>',
              f'ros2 lifecycle set {node_path} configure',
              f'ros2 lifecycle set {node_path} activate']
    return (f'{name} is read on configure and the node is {state} with {name} {current!r}; '
            f'to change it: ' + '; '.join(steps))


def configure_failed_hint(node_path: str, parameter: str = 'robot_config') -> str:
    """What to do after a failed configure: the node stays unconfigured until then."""
    return (f'the node stays unconfigured (no pressure commands); to recover: '
            f'ros2 param set {node_path} {parameter} <shipped robot name or robot YAML path>, '
            f'then ros2 lifecycle set {node_path} configure and '
            f'ros2 lifecycle set {node_path} activate')
