"""The nodes' message contract and the pressure safety gate (plain numbers, no rclpy import).

* pressure units and the ``Float64MultiArray`` layout label
  (:func:`pressure_label`, :func:`to_unit`, :func:`from_unit`): gauge
  pressures, Pa inside the package (REP-103 SI units), ``Pa`` or ``kPa`` on
  a topic as a node's ``pressure_unit`` parameter says;
* the pressure safety gate :func:`safe_pressures`, through which every
  pressure a node publishes passes (refuses NaN, inf, a wrong count and
  anything outside ``[p_min, p_max]``), and :func:`vent_pressures`;
* validation of incoming data: :func:`validate_target` (target pose),
  :func:`validate_pressure_input` (pressure arrays for the forward node),
  :func:`validate_payload`, :func:`parameter_problem` (run-time parameters);
* the texts that tell a user how to get out of a refused or failed state
  (:func:`configure_time_refusal`, :func:`configure_failed_hint`).

Quaternions follow :mod:`bellow_ancf_ros.core.geometry` (ROS order x, y, z, w).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..core.geometry import z_axis_from_quaternion
from ..core.model import MAX_TIP_FORCE_N

__all__ = [
    'PAYLOAD_MAX_KG', 'PRESSURE_UNITS', 'InputError', 'UnsafePressureError', 'check_unit',
    'configure_failed_hint', 'configure_time_refusal', 'from_unit', 'parameter_problem',
    'pressure_label', 'safe_pressures', 'to_unit', 'unit_from_label', 'validate_payload',
    'validate_force', 'validate_pressure_input', 'validate_target', 'vent_pressures',
]

#: Pressure units accepted by the ``pressure_unit`` parameters: factor to Pa.
PRESSURE_UNITS = {'Pa': 1.0, 'kPa': 1e3}

#: Largest payload the nodes accept [kg] (the paper uses 0-100 g).
PAYLOAD_MAX_KG = 1.0

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
    """Why a node parameter value is refused ('' if it is fine): key, value, what is allowed.

    Shared by the nodes' set-parameters callbacks: ``payload_kg``,
    ``pressure_unit``, ``max_rate_hz``, ``base_frame``, ``robot_config``
    (must load); other names are not checked here.
    """
    allowed = ''
    try:
        if name == 'payload_kg':
            validate_payload(value)
        elif name == 'pressure_unit' and value not in PRESSURE_UNITS:
            allowed = ' or '.join(map(repr, sorted(PRESSURE_UNITS)))
        elif name == 'max_rate_hz' and not (isinstance(value, float) and math.isfinite(value)
                                            and value > 0):
            allowed = 'a positive number of Hz'
        elif name == 'base_frame' and (not isinstance(value, str) or not value):
            allowed = 'a non-empty frame name'
        elif name == 'robot_config':
            from ..core import load_robot
            load_robot(value)  # takes effect on the next configure
    except ValueError as exc:  # ConfigError is a ValueError
        return f'{name} = {value!r} is not allowed: {exc}'
    return f'{name} = {value!r} is not allowed; allowed: {allowed}' if allowed else ''


# ---------------------------------------------------------------- targets
def _require_base_frame(what: str, frame_id: str, base_frame: str) -> None:
    """Raise InputError unless ``frame_id`` is ``base_frame`` (an empty one too: no tf2 here)."""
    if frame_id != base_frame:
        raise InputError(f"{what} frame {frame_id!r} is not the base frame {base_frame!r} "
                         '(no tf2 transform is done)')


def validate_target(position: Sequence[float], quaternion: Sequence[float] | None,
                    frame_id: str, base_frame: str, use_orientation: bool):
    """Check a target pose; return ``(position (3,), z_axis (3,) or None)``.

    Raises :class:`InputError` naming the reason for a wrong frame, a
    non-finite position, or (when ``use_orientation``) a quaternion that is
    non-finite or cannot be normalised.  An empty ``frame_id`` is refused too:
    without tf2 the node cannot know what frame was meant.
    """
    _require_base_frame('target', frame_id, base_frame)
    p = np.array(position, dtype=float).ravel()
    if p.size != 3 or not np.all(np.isfinite(p)):
        raise InputError(f'target position must be 3 finite numbers, got {p.tolist()}')
    try:
        z = z_axis_from_quaternion(quaternion) if use_orientation else None
    except ValueError as exc:  # not 4 finite components, or ~zero
        raise InputError(str(exc)) from None
    return p, z


def validate_force(force: Sequence[float], frame_id: str, base_frame: str) -> np.ndarray:
    """Check a force at the end effector (a WrenchStamped's force) and return it [N].

    Raises :class:`InputError` for a frame other than the base frame (an
    empty one too), non-finite components, or a magnitude above
    ``MAX_TIP_FORCE_N`` (a unit mistake).
    """
    _require_base_frame('force', frame_id, base_frame)
    f = np.array(force, dtype=float).ravel()
    if f.size != 3 or not np.all(np.isfinite(f)):
        raise InputError(f'force must be 3 finite numbers, got {f.tolist()}')
    size = float(np.linalg.norm(f))
    if size > MAX_TIP_FORCE_N:
        raise InputError(f'force of {size:.3g} N is above {MAX_TIP_FORCE_N:g} N (a unit mistake?)')
    return f


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
