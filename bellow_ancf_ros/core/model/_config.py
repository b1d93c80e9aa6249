"""Robot description: YAML loader, validation and SI dataclasses.

A robot file (``config/one_segment.yaml``, ``config/two_segment.yaml``; schema
in docs/model.md section 5) carries the unit of every non-SI value in its key
name (``pitch_radius_mm``, ``p_max_kpa``).  :func:`load_robot` reads such a
file, checks it completely and returns a frozen :class:`RobotConfig` whose
values are all SI (m, kg, Pa, rad, N/m).

Every problem is reported as a :class:`ConfigError` that names the full dotted
key (``segments[1].connector_height_mm``; list indices are zero-based) and the
reason; all problems found in one file are reported together.

Shipped robot names are looked up, first match wins, in

a. the ament index share directory of ``bellow_ancf_ros`` (``config/``
   below it, then the share directory itself), if ``ament_index_python`` is
   importable and knows the package;
b. the source tree: ``config/`` next to the ``bellow_ancf_ros`` package
   directory (repository checkout, ``pip install -e .``);
c. ``<sys.prefix>/share/bellow_ancf_ros/config`` (``pip install .``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
import dataclasses
from dataclasses import dataclass, field
import difflib
import math
import numbers
import os
from pathlib import Path
import sys
from typing import Any, Iterable

import numpy as np
import yaml

from ..geometry import (QUATERNION_MIN_NORM, quaternion_from_rotation, quaternion_to_rotation,
                        unit_quaternion)
from ._stage1 import Stage1

__all__ = [
    'ConfigError',
    'MocapFrame',
    'SegmentConfig',
    'RobotConfig',
    'load_robot',
    'robot_from_dict',
    'config_dirs',
    'find_shipped',
    'shipped_robot_names',
    'plate_support_problem',
    'smallest_element_count',
    'check_element_count',
]

PACKAGE_NAME = 'bellow_ancf_ros'


# --------------------------------------------------------------------- errors
class ConfigError(ValueError):
    """Invalid robot description.

    Attributes
    ----------
    issues: list of (key, reason)
        Every problem found; ``key`` is the full dotted key (or the file path /
        robot name for problems with the file itself).
    key: str
        Key of the first issue.
    source: str
        File (or ``'<dict>'``) the description came from.
    """

    def __init__(self, issues: Iterable[tuple[str, str]], source: str = '<dict>') -> None:
        self.issues = list(issues)
        self.source = source
        self.key = self.issues[0][0] if self.issues else ''
        lines = [reason if key == source else f'{key}: {reason}' for key, reason in self.issues]
        if len(lines) == 1:
            message = f'{source}: {lines[0]}'
        else:
            message = f'{source}: {len(lines)} problems: ' + '; '.join(lines)   # one line
        super().__init__(message)


# ---------------------------------------------------------------- dataclasses
@dataclass(frozen=True)
class SegmentConfig:
    """One segment of the robot (SI units).

    Attributes
    ----------
    n_actuators: number of actuators ``n_a`` (>= 3).
    pitch_radius: radius ``R`` of the actuator circle [m].
    theta0: angle of actuator 1 about the plate normal [rad]; actuator ``i``
        (1-based) sits at ``theta0 + 2*pi*(i-1)/n_a``.
    plate_fractions: material fractions of the intermediate constraint plates
        (base plate 0 and top plate 1 excluded), strictly increasing in (0, 1).
    constraint_plate_mass: mass of each intermediate plate [kg].
    top_plate_mass: mass of the top plate [kg].
    connector_height: height ``h_c`` of the connector below this segment [m]
        (0.0 for segment 1, which stands on the fixed base).
    connector_mass: mass of that connector [kg] (0.0 for segment 1).
    plate_radius: radius of this segment's plates as thin discs [m] (dynamics only,
        ``plate_radius_mm``); None: ``R + D_a/2`` (:func:`RobotConfig.plate_radius_of`).
    """

    n_actuators: int
    pitch_radius: float
    theta0: float
    plate_fractions: tuple[float, ...]
    constraint_plate_mass: float
    top_plate_mass: float
    connector_height: float = 0.0
    connector_mass: float = 0.0
    plate_radius: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, 'plate_fractions',
                           tuple(float(s) for s in self.plate_fractions))

    @property
    def actuator_angles(self) -> np.ndarray:
        """Angles ``theta_i = theta0 + 2*pi*(i-1)/n_a`` of the actuators [rad]."""
        return self.theta0 + 2.0 * np.pi * np.arange(self.n_actuators) / self.n_actuators


@dataclass(frozen=True)
class MocapFrame:
    """Where the motion capture sees the robot: the pose of the base frame in the mocap frame.

    Attributes
    ----------
    frame_id: the mocap frame's name (``header.frame_id`` of its poses).
    position: the base frame's origin in the mocap frame [m].
    quaternion_xyzw: the base frame's orientation in the mocap frame (unit,
        ROS order x, y, z, w): its rotation's columns are the base axes in
        mocap coordinates.

    ``bellow-ancf calibrate`` fits it and writes it to the calibrated robot
    file (key ``mocap_frame``); nodes that take measured poses use it to
    express mocap poses in the base frame (:meth:`to_base`).
    """

    frame_id: str
    position: tuple[float, float, float]
    quaternion_xyzw: tuple[float, float, float, float]

    def __post_init__(self) -> None:
        object.__setattr__(self, 'position', tuple(float(v) for v in self.position))
        q = np.asarray(self.quaternion_xyzw, dtype=float)
        if not abs(np.linalg.norm(q) - 1.0) <= 1e-14:   # (a unit one stays bit for bit)
            q = unit_quaternion(q)
        object.__setattr__(self, 'quaternion_xyzw', tuple(float(v) for v in q))

    @property
    def rotation(self) -> np.ndarray:
        """Base axes in mocap coordinates (columns)."""
        return quaternion_to_rotation(self.quaternion_xyzw)

    def to_base(self, position, quaternion_xyzw=None):
        """A pose in the mocap frame expressed in the base frame: ``(position, quaternion)``.

        ``p_base = R^T (p_mocap - t)``, ``R_base = R^T R_mocap`` (quaternion
        None: only the position).  Raises ValueError for a bad quaternion.
        """
        R = self.rotation
        p = R.T @ (np.asarray(position, dtype=float).reshape(3) - np.asarray(self.position))
        if quaternion_xyzw is None:
            return p, None
        return p, quaternion_from_rotation(R.T @ quaternion_to_rotation(quaternion_xyzw))

    def from_base(self, position, rotation):
        """A pose in the base frame as the mocap sees it: ``(R p + t, R R_pose)``.

        The inverse of :meth:`to_base`; ``rotation`` is a rotation matrix.
        """
        R = self.rotation
        return (R @ np.asarray(position, dtype=float).reshape(3) + np.asarray(self.position),
                R @ np.asarray(rotation, dtype=float))

    def to_dict(self) -> dict[str, Any]:
        """The ``mocap_frame`` entry of a robot file."""
        return {'frame_id': self.frame_id, 'position_m': list(self.position),
                'quaternion_xyzw': list(self.quaternion_xyzw)}


@dataclass(frozen=True)
class RobotConfig:
    """Complete robot description (SI units).

    Attributes
    ----------
    name: robot name.
    l0: unpressurised actuator length [m].
    stiffness_coeffs: ``k(lam)`` coefficients, ascending powers [N/m].
    d_eff: effective actuation diameter ``D_eff`` [m].
    d_a: cross-sectional diameter ``D_a`` [m].
    rho0: unstretched actuator linear density [kg/m].
    segments: the segments, base to tip.
    p_min, p_max: gauge pressure limits of every actuator [Pa].
    n_elements: ANCF elements per actuator.
    gravity: gravity vector in the base frame [m/s^2].
    tool_length: end-effector offset along the last top-plate normal [m].
    payload: point mass at the end effector [kg].
    mocap_frame: where the motion capture sees the robot (:class:`MocapFrame`),
        or None (measured poses come in the base frame).
    damping_time: Kelvin-Voigt retardation time ``beta`` of the actuator strains [s]
        (dynamics only, ``dynamics.damping_time_s``; default :data:`DEFAULT_DAMPING_TIME_S`).
    mass_damping: mass-proportional (air) damping ``alpha`` [1/s] (dynamics only,
        ``dynamics.mass_damping_per_s``; default 0).
    first_mode_error: the model's first mode over the robot's measured one, minus
        one (``dynamics.first_mode_error``, as ``bellow-ancf identify damping``
        prints it), or None: not measured.  The closed loop sizes a target
        jump's move to the robot's mode when it is known within
        :data:`~bellow_ancf_ros.core.control.KNOWN_MODE_ERROR`.
    source: where the description came from (not compared by ``==``).
    """

    name: str
    l0: float
    stiffness_coeffs: tuple[float, ...]
    d_eff: float
    d_a: float
    rho0: float
    segments: tuple[SegmentConfig, ...]
    p_min: float
    p_max: float
    n_elements: int
    gravity: tuple[float, float, float]
    tool_length: float
    payload: float
    mocap_frame: MocapFrame | None = None
    damping_time: float = 0.005
    mass_damping: float = 0.0
    first_mode_error: float | None = None
    source: str = field(default='<dict>', compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, 'stiffness_coeffs',
                           tuple(float(c) for c in self.stiffness_coeffs))
        object.__setattr__(self, 'segments', tuple(self.segments))
        object.__setattr__(self, 'gravity', tuple(float(g) for g in self.gravity))

    @property
    def n_segments(self) -> int:
        """Number of segments ``m``."""
        return len(self.segments)

    @property
    def n_actuators_total(self) -> int:
        """Number of actuators over all segments."""
        return sum(s.n_actuators for s in self.segments)

    @property
    def actuator_slices(self) -> list[slice]:
        """Per segment, the slice of its actuators in the global actuator order."""
        out, start = [], 0
        for seg in self.segments:
            out.append(slice(start, start + seg.n_actuators))
            start += seg.n_actuators
        return out

    def plate_radius_of(self, j: int) -> float:
        """Radius of segment ``j``'s plates as thin discs [m].

        Its ``plate_radius_mm``, else ``R + D_a/2`` (the discs reach the
        actuators' outer edges).
        """
        seg = self.segments[j]
        return seg.plate_radius if seg.plate_radius is not None \
            else seg.pitch_radius + 0.5 * self.d_a

    def replace(self, **changes: Any) -> 'RobotConfig':
        """Copy with some fields changed (:func:`dataclasses.replace`, no validation)."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """The description in the YAML schema (file units), inverse of :func:`robot_from_dict`."""
        segments = []
        for j, seg in enumerate(self.segments):
            d = {
                'n_actuators': seg.n_actuators,
                'pitch_radius_mm': seg.pitch_radius * 1e3,
                'theta0_deg': math.degrees(seg.theta0),
                'constraint_plate_fractions': list(seg.plate_fractions),
                'constraint_plate_mass_kg': seg.constraint_plate_mass,
                'top_plate_mass_kg': seg.top_plate_mass,
            }
            if j > 0:
                d['connector_height_mm'] = seg.connector_height * 1e3
                d['connector_mass_kg'] = seg.connector_mass
            if seg.plate_radius is not None:
                d['plate_radius_mm'] = seg.plate_radius * 1e3
            segments.append(d)
        d = {
            'name': self.name,
            'actuator': {
                'l0_m': self.l0,
                'stiffness_coeffs_n_per_m': list(self.stiffness_coeffs),
                'd_eff_mm': self.d_eff * 1e3,
                'd_a_mm': self.d_a * 1e3,
                'linear_density_kg_per_m': self.rho0,
            },
            'segments': segments,
            'pressure_limits': {'p_min_kpa': self.p_min / 1e3, 'p_max_kpa': self.p_max / 1e3},
            'model': {
                'n_elements': self.n_elements,
                'gravity_m_per_s2': list(self.gravity),
                'tool_length_mm': self.tool_length * 1e3,
            },
            'payload_kg': self.payload,
            'dynamics': {'damping_time_s': self.damping_time,
                         'mass_damping_per_s': self.mass_damping},
        }
        if self.first_mode_error is not None:
            d['dynamics']['first_mode_error'] = self.first_mode_error
        if self.mocap_frame is not None:
            d['mocap_frame'] = self.mocap_frame.to_dict()
        return d


# --------------------------------------------------------------------- schema
_TOP_KEYS = ('name', 'actuator', 'segments', 'pressure_limits', 'model', 'payload_kg')
_OPTIONAL_TOP_KEYS = ('mocap_frame', 'dynamics')
_DYNAMICS_KEYS = ('damping_time_s', 'mass_damping_per_s', 'first_mode_error')
#: Allowed ``dynamics.first_mode_error``: a model whose first mode is farther off is
#: recalibrated (``mass_scale``), not corrected by a number.
FIRST_MODE_ERROR_RANGE = (-0.5, 1.0)
#: Kelvin-Voigt retardation time of a robot file without ``dynamics.damping_time_s`` [s]:
#: a loss factor of about 0.1 at a few Hz (polyurethane and silicone elastomers of
#: Shore 30-60 A: tan delta 0.05-0.3), docs/dynamics.md.
DEFAULT_DAMPING_TIME_S = 0.005
_MOCAP_KEYS = ('frame_id', 'position_m', 'quaternion_xyzw')
_ACTUATOR_KEYS = ('l0_m', 'stiffness_coeffs_n_per_m', 'd_eff_mm', 'd_a_mm',
                  'linear_density_kg_per_m')
_SEGMENT_KEYS = ('n_actuators', 'pitch_radius_mm', 'theta0_deg', 'constraint_plate_fractions',
                 'constraint_plate_mass_kg', 'top_plate_mass_kg')
_CONNECTOR_KEYS = ('connector_height_mm', 'connector_mass_kg')
_PRESSURE_KEYS = ('p_min_kpa', 'p_max_kpa')
_MODEL_KEYS = ('n_elements', 'gravity_m_per_s2', 'tool_length_mm')

_MISSING = object()


def _is_number(v: Any) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_))


def _is_integer(v: Any) -> bool:
    return isinstance(v, numbers.Integral) and not isinstance(v, (bool, np.bool_))


def _type_name(v: Any) -> str:
    return 'null' if v is None else type(v).__name__


class _Checker:
    """Collects (key, reason) issues while reading a nested description."""

    def __init__(self) -> None:
        self.issues: list[tuple[str, str]] = []

    def err(self, key: str, reason: str) -> None:
        self.issues.append((key, reason))

    @staticmethod
    def join(path: str, key: str) -> str:
        return f'{path}.{key}' if path else key

    def mapping(self, value: Any, path: str, allowed: Sequence[str],
                forbidden: Mapping[str, str] | None = None,
                optional: Sequence[str] = ()) -> Mapping | None:
        """Check that ``value`` is a mapping without unknown keys; report missing ones.

        ``optional`` keys may be there or not.
        """
        if not isinstance(value, Mapping):
            self.err(path or '<top level>', f'expected a mapping, got {_type_name(value)}')
            return None
        forbidden = forbidden or {}
        for key in value:
            if key in allowed or key in optional:
                continue
            full = self.join(path, str(key))
            if key in forbidden:
                self.err(full, forbidden[key])
                continue
            known = tuple(allowed) + tuple(optional)
            close = difflib.get_close_matches(str(key), known, n=1, cutoff=0.6)
            hint = f"did you mean '{close[0]}'?" if close else \
                'allowed keys: ' + ', '.join(known)
            self.err(full, f'unknown key; {hint}')
        for key in allowed:
            if key not in value:
                self.err(self.join(path, key), 'missing required key')
        return value

    def number(self, m: Mapping, path: str, key: str, *, positive: bool = False,
               nonneg: bool = False) -> float | None:
        """Return ``m[key]`` as a finite real number; int accepted, bool refused."""
        v = m.get(key, _MISSING)
        if v is _MISSING:
            return None                       # reported by mapping()
        return self._number_value(v, self.join(path, key), positive=positive, nonneg=nonneg)

    def _number_value(self, v: Any, full: str, *, positive: bool = False,
                      nonneg: bool = False) -> float | None:
        if not _is_number(v):
            self.err(full, f'expected a number, got {_type_name(v)} ({v!r})')
            return None
        x = float(v)
        if not math.isfinite(x):
            self.err(full, f'must be finite, got {x!r}')
            return None
        if positive and not x > 0.0:
            self.err(full, f'must be positive (> 0), got {v!r}')
            return None
        if nonneg and not x >= 0.0:
            self.err(full, f'must not be negative (>= 0), got {v!r}')
            return None
        return x

    def integer(self, m: Mapping, path: str, key: str, minimum: int, why: str = '') -> int | None:
        """Return ``m[key]`` as an integer >= ``minimum``; no bool, no float."""
        v = m.get(key, _MISSING)
        if v is _MISSING:
            return None
        full = self.join(path, key)
        if not _is_integer(v):
            self.err(full, f'expected an integer, got {_type_name(v)} ({v!r})')
            return None
        if int(v) < minimum:
            self.err(full, f'must be >= {minimum}{why}, got {v!r}')
            return None
        return int(v)

    def numbers(self, m: Mapping, path: str, key: str, *, length: int | None = None,
                nonempty: bool = False) -> tuple[float, ...] | None:
        """A list of finite numbers, optionally of fixed length / non-empty."""
        v = m.get(key, _MISSING)
        if v is _MISSING:
            return None
        full = self.join(path, key)
        if isinstance(v, (str, bytes, Mapping)) or not isinstance(v, Sequence):
            self.err(full, f'expected a list of numbers, got {_type_name(v)} ({v!r})')
            return None
        if length is not None and len(v) != length:
            self.err(full, f'expected exactly {length} numbers, got {len(v)}')
            return None
        if nonempty and len(v) == 0:
            self.err(full, 'must not be empty')
            return None
        out = [self._number_value(x, f'{full}[{i}]') for i, x in enumerate(v)]
        if any(x is None for x in out):
            return None
        return tuple(out)

    def string(self, m: Mapping, path: str, key: str) -> str | None:
        v = m.get(key, _MISSING)
        if v is _MISSING:
            return None
        full = self.join(path, key)
        if not isinstance(v, str) or not v.strip():
            self.err(full, f'expected a non-empty string, got {_type_name(v)} ({v!r})')
            return None
        return v


def _segment(chk: _Checker, value: Any, j: int) -> SegmentConfig | None:
    path = f'segments[{j}]'
    if j == 0:
        reason = ('not allowed on the first segment (it stands on the fixed base plate); '
                  'connector keys belong to segments 2..m')
        m = chk.mapping(value, path, _SEGMENT_KEYS, dict.fromkeys(_CONNECTOR_KEYS, reason),
                        optional=('plate_radius_mm',))
    else:
        m = chk.mapping(value, path, _SEGMENT_KEYS + _CONNECTOR_KEYS,
                        optional=('plate_radius_mm',))
    if m is None:
        return None
    n_a = chk.integer(m, path, 'n_actuators', 3, ' (three actuators determine a plate)')
    radius = chk.number(m, path, 'pitch_radius_mm', positive=True)
    theta0 = chk.number(m, path, 'theta0_deg')
    fractions = chk.numbers(m, path, 'constraint_plate_fractions')
    if fractions is not None:
        key = f'{path}.constraint_plate_fractions'
        if any(not 0.0 < s < 1.0 for s in fractions):
            chk.err(key, f'every plate fraction must lie strictly between 0 and 1 '
                         f'(base and top plates are implicit), got {list(fractions)}')
            fractions = None
        elif any(b <= a for a, b in zip(fractions, fractions[1:])):
            chk.err(key, f'plate fractions must be strictly increasing, got {list(fractions)}')
            fractions = None
    m_plate = chk.number(m, path, 'constraint_plate_mass_kg', nonneg=True)
    m_top = chk.number(m, path, 'top_plate_mass_kg', nonneg=True)
    if j > 0:
        h_c = chk.number(m, path, 'connector_height_mm', positive=True)
        m_c = chk.number(m, path, 'connector_mass_kg', nonneg=True)
    else:
        h_c = m_c = 0.0
    values = (n_a, radius, theta0, fractions, m_plate, m_top, h_c, m_c)
    r_plate = None
    if 'plate_radius_mm' in m:
        r_plate = chk.number(m, path, 'plate_radius_mm', positive=True)
        if r_plate is None:
            return None
        r_plate *= 1e-3
    if any(v is None for v in values):
        return None
    return SegmentConfig(
        n_actuators=n_a,
        pitch_radius=radius * 1e-3,
        theta0=math.radians(theta0),
        plate_fractions=fractions,
        constraint_plate_mass=m_plate,
        top_plate_mass=m_top,
        connector_height=h_c * 1e-3,
        connector_mass=m_c,
        plate_radius=r_plate,
    )


# ------------------------------------------------------- element count
_MAX_ELEMENTS_SEARCHED = 1000


def plate_support_problem(fractions: Sequence[float], n: int, tol: float = 1e-9) -> str | None:
    """Why ``n`` uniform cubic elements cannot carry plates at ``fractions`` (None: they can).

    Every attachment (base 0, the plates, top 1) fixes an actuator's position
    and direction at its material point.  One cubic element (eq. 6) can meet
    such conditions at two points at most; an element tied at two points has
    its nodal values fixed by them, which ties its neighbour at the shared
    node too.  Propagating that along the actuator, a count is refused when
    an element ends up tied at three or more points: the plates then lock the
    actuator (a converged, stable and wrong shape) or make the equations
    singular.  Measured against a fine reference, every count this accepts
    is accurate (test/test_config.py).
    """
    n = int(n)
    points = (0.0, *[float(f) for f in fractions], 1.0)

    def key(s):
        k = round(s * n)
        return ('node', k) if abs(s * n - k) < tol else ('point', s)

    per_element = [set() for _ in range(n)]
    received = [set() for _ in range(n)]  # node keys an element was tied at by a neighbour
    for s in points:
        for e in range(n):
            if e / n - tol <= s <= (e + 1) / n + tol:
                per_element[e].add(key(s))
    changed = True
    while changed:
        changed = False
        for e in range(n):
            if len(per_element[e]) >= 3:
                return (f'element {e + 1} of {n} (actuator fractions {e / n:.4g} to '
                        f'{(e + 1) / n:.4g}) would be tied at {len(per_element[e])} points')
            if len(per_element[e]) != 2:
                continue
            for k, nb in ((e, e - 1), (e + 1, e + 1)):
                node = ('node', k)
                if 0 <= nb < n and node not in received[e] and node not in per_element[nb]:
                    per_element[nb].add(node)
                    received[nb].add(node)
                    changed = True
    return None


def smallest_element_count(segments: Sequence[SegmentConfig]) -> int | None:
    """Smallest element count that carries the plates of every segment (None: none up to 1000)."""
    for n in range(1, _MAX_ELEMENTS_SEARCHED + 1):
        if all(plate_support_problem(seg.plate_fractions, n) is None for seg in segments):
            return n
    return None


def _element_count_issue(segments: Sequence[SegmentConfig], n: int) -> tuple[str, str] | None:
    """``(key, reason)`` when ``n`` elements cannot carry the plates, else None.

    Counts above ``_MAX_ELEMENTS_SEARCHED`` are refused first: checking them
    takes time and memory in proportion to ``n`` (a file with ``10**12`` would
    exhaust the machine before any answer).
    """
    if n > _MAX_ELEMENTS_SEARCHED:
        return ('model.n_elements', f'at most {_MAX_ELEMENTS_SEARCHED} elements per actuator '
                                    f'are allowed, got {n}')
    for j, seg in enumerate(segments):
        why = plate_support_problem(seg.plate_fractions, n)
        if why is None:
            continue
        best = smallest_element_count(segments)
        fractions = '[' + ', '.join(f'{f:.6g}' for f in seg.plate_fractions) + ']'
        if best is None:
            return (f'segments[{j}].constraint_plate_fractions',
                    f'plates at {fractions} are too close together for up to '
                    f'{_MAX_ELEMENTS_SEARCHED} elements per actuator')
        return ('model.n_elements',
                f'{n} elements per actuator cannot carry the plates of segment {j + 1} at '
                f'fractions {fractions}: {why}; the smallest count that works is {best}')
    return None


def check_element_count(cfg: 'RobotConfig', n: int) -> None:
    """Raise :class:`ConfigError` (key ``model.n_elements``) when ``n`` cannot carry the plates."""
    issue = _element_count_issue(cfg.segments, n)
    if issue is not None:
        raise ConfigError([issue], cfg.source)


def robot_from_dict(d: Any, source: str = '<dict>') -> RobotConfig:
    """Validate a description in the YAML schema and convert it to SI.

    Raises :class:`ConfigError` listing every problem found.
    """
    chk = _Checker()
    top = chk.mapping(d, '', _TOP_KEYS, optional=_OPTIONAL_TOP_KEYS)
    if top is None:
        raise ConfigError(chk.issues, source)

    name = chk.string(top, '', 'name')

    act = chk.mapping(top['actuator'], 'actuator', _ACTUATOR_KEYS) \
        if 'actuator' in top else None
    l0 = d_eff = d_a = rho0 = coeffs = None
    if act is not None:
        l0 = chk.number(act, 'actuator', 'l0_m', positive=True)
        coeffs = chk.numbers(act, 'actuator', 'stiffness_coeffs_n_per_m', nonempty=True)
        d_eff = chk.number(act, 'actuator', 'd_eff_mm', positive=True)
        d_a = chk.number(act, 'actuator', 'd_a_mm', positive=True)
        rho0 = chk.number(act, 'actuator', 'linear_density_kg_per_m', nonneg=True)

    segments: list[SegmentConfig | None] | None = None
    if 'segments' in top:
        raw = top['segments']
        if isinstance(raw, (str, bytes, Mapping)) or not isinstance(raw, Sequence):
            chk.err('segments', f'expected a list of segments, got {_type_name(raw)}')
        elif len(raw) == 0:
            chk.err('segments', 'at least one segment is required')
        else:
            segments = [_segment(chk, s, j) for j, s in enumerate(raw)]

    p_min = p_max = None
    if 'pressure_limits' in top:
        pl = chk.mapping(top['pressure_limits'], 'pressure_limits', _PRESSURE_KEYS)
        if pl is not None:
            p_min = chk.number(pl, 'pressure_limits', 'p_min_kpa')
            p_max = chk.number(pl, 'pressure_limits', 'p_max_kpa')
            if p_min is not None and p_max is not None and not p_min < p_max:
                chk.err('pressure_limits.p_min_kpa',
                        f'must be smaller than pressure_limits.p_max_kpa '
                        f'(got p_min_kpa={p_min!r} >= p_max_kpa={p_max!r})')
                p_min = p_max = None

    n_elements = gravity = tool = None
    if 'model' in top:
        mod = chk.mapping(top['model'], 'model', _MODEL_KEYS)
        if mod is not None:
            n_elements = chk.integer(mod, 'model', 'n_elements', 1)
            gravity = chk.numbers(mod, 'model', 'gravity_m_per_s2', length=3)
            tool = chk.number(mod, 'model', 'tool_length_mm', nonneg=True)

    payload = chk.number(top, '', 'payload_kg', nonneg=True)
    mocap = _mocap_frame(chk, top['mocap_frame']) if 'mocap_frame' in top else None
    damping_time, mass_damping, mode_error = DEFAULT_DAMPING_TIME_S, 0.0, None
    if 'dynamics' in top:
        dyn = chk.mapping(top['dynamics'], 'dynamics', (), optional=_DYNAMICS_KEYS)
        if dyn is not None:
            if 'damping_time_s' in dyn:
                damping_time = chk.number(dyn, 'dynamics', 'damping_time_s', nonneg=True)
            if 'mass_damping_per_s' in dyn:
                mass_damping = chk.number(dyn, 'dynamics', 'mass_damping_per_s', nonneg=True)
            if 'first_mode_error' in dyn:
                mode_error = chk.number(dyn, 'dynamics', 'first_mode_error')
                lo, hi = FIRST_MODE_ERROR_RANGE
                if mode_error is not None and not lo <= mode_error <= hi:
                    chk.err('dynamics.first_mode_error',
                            f'{mode_error!r} is not from {lo:g} to {hi:g} (the model\'s first '
                            'mode over the measured one, minus one: farther off, calibrate '
                            'the file again with mass_scale)')
                    mode_error = None

    # A finite number in the file can still leave the floating-point range in SI.
    for key, value in (('p_min_kpa', p_min), ('p_max_kpa', p_max)):
        if value is not None and not math.isfinite(value * 1e3):
            chk.err(f'pressure_limits.{key}',
                    f'{value!r} kPa overflows in Pa (|p| must be below 1.7e305 kPa)')
            p_min = p_max = None
    if d_eff is not None and l0 is not None:
        d = d_eff * 1e-3
        area = math.pi / 4.0 * d * d
        if not (0.0 < area < math.inf and l0 / area < math.inf):
            chk.err('actuator.d_eff_mm',
                    f'{d_eff!r} mm leaves the floating-point range: the actuation area '
                    f'pi/4 D_eff**2 = {area!r} m^2 and l0_m/area must be positive and finite')
            d_eff = None

    # Stage 1 must map [p_min, p_max] monotonically (docs/model.md section 2).
    if None not in (coeffs, l0, d_eff, p_min, p_max):
        try:
            Stage1(coeffs, l0, d_eff * 1e-3, p_min * 1e3, p_max * 1e3)
        except ValueError as exc:
            chk.err('actuator.stiffness_coeffs_n_per_m', str(exc))

    if n_elements is not None and segments is not None and None not in segments:
        issue = _element_count_issue(segments, n_elements)
        if issue is not None:
            chk.err(*issue)

    if chk.issues:
        raise ConfigError(chk.issues, source)
    assert segments is not None and None not in segments
    return RobotConfig(
        name=name,
        l0=l0,
        stiffness_coeffs=coeffs,
        d_eff=d_eff * 1e-3,
        d_a=d_a * 1e-3,
        rho0=rho0,
        segments=tuple(segments),
        p_min=p_min * 1e3,
        p_max=p_max * 1e3,
        n_elements=n_elements,
        gravity=gravity,
        tool_length=tool * 1e-3,
        payload=payload,
        mocap_frame=mocap,
        damping_time=damping_time,
        mass_damping=mass_damping,
        first_mode_error=mode_error,
        source=source,
    )


def _mocap_frame(chk: _Checker, raw: Any) -> MocapFrame | None:
    """The optional ``mocap_frame`` entry (frame name, position [m], unit quaternion)."""
    m = chk.mapping(raw, 'mocap_frame', _MOCAP_KEYS)
    if m is None:
        return None
    frame = chk.string(m, 'mocap_frame', 'frame_id')
    pos = chk.numbers(m, 'mocap_frame', 'position_m', length=3)
    quat = chk.numbers(m, 'mocap_frame', 'quaternion_xyzw', length=4)
    if quat is not None and not np.linalg.norm(quat) > QUATERNION_MIN_NORM:
        chk.err('mocap_frame.quaternion_xyzw', f'must be a non-zero quaternion, got {list(quat)}')
        quat = None
    if None in (frame, pos, quat):
        return None
    return MocapFrame(frame, pos, quat)


# ---------------------------------------------------------------- file access
class _UniqueKeyLoader(yaml.SafeLoader):
    """Safe YAML loader that refuses duplicate mapping keys."""


def _construct_unique_mapping(loader: yaml.SafeLoader, node: yaml.MappingNode,
                              deep: bool = False) -> dict:
    loader.flatten_mapping(node)
    seen = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=True)
        try:
            duplicate = key in seen
        except TypeError:                    # unhashable: reported by PyYAML below
            continue
        if duplicate:
            raise yaml.constructor.ConstructorError(
                'while constructing a mapping', node.start_mark,
                f'found duplicate key {key!r}', key_node.start_mark)
        seen.add(key)
    return loader.construct_mapping(node, deep=deep)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG,
                                 _construct_unique_mapping)


def config_dirs() -> list[Path]:
    """Directories searched for shipped robot files, in order (see module doc)."""
    dirs: list[Path] = []
    try:
        from ament_index_python.packages import get_package_share_directory
        share = Path(get_package_share_directory(PACKAGE_NAME))
        dirs += [share / 'config', share]
    except Exception:  # noqa: BLE001 - not importable, no index, package unknown
        pass
    dirs.append(Path(__file__).resolve().parents[3] / 'config')  # the source tree's config/
    dirs.append(Path(sys.prefix) / 'share' / PACKAGE_NAME / 'config')
    return dirs


def shipped_robot_names() -> list[str]:
    """Names of the robot files found in :func:`config_dirs`."""
    names = set()
    for d in config_dirs():
        if d.is_dir():
            # ROS parameter files (config/nodes.yaml) share the folder; they are not robots
            names.update(
                p.stem for p in d.glob('*.yaml')
                if 'ros__parameters' not in p.read_text(encoding='utf-8', errors='replace'))
    return sorted(names)


def find_shipped(name: str) -> Path:
    """Path of the shipped robot file ``name`` (first match in :func:`config_dirs`)."""
    dirs = config_dirs()
    for d in dirs:
        candidate = d / f'{name}.yaml'
        if candidate.is_file():
            return candidate
    raise ConfigError([(name, 'unknown robot name; shipped robots: '
                        + (', '.join(shipped_robot_names()) or '(none found)')
                        + '; searched: ' + ', '.join(str(d) for d in dirs))], name)


def _looks_like_path(name_or_path: str | os.PathLike) -> bool:
    if isinstance(name_or_path, os.PathLike):
        return True
    s = str(name_or_path)
    return (os.sep in s or (os.altsep is not None and os.altsep in s) or '/' in s
            or s.endswith(('.yaml', '.yml')))


def load_robot(name_or_path: str | os.PathLike) -> RobotConfig:
    """Load and validate a robot description.

    ``name_or_path`` is a shipped robot name (``'one_segment'``,
    ``'two_segment'``; no path separator, no ``.yaml`` suffix) or the path of
    a YAML file.  Raises :class:`ConfigError` for an unknown name, a missing
    or unreadable file, a YAML syntax error (or duplicate key) and every
    invalid value.

    A robot loaded from a path is named by its file (``name`` = the file's
    stem, ``my_robot`` for ``lab/my_robot.yaml``), whatever its ``name:``
    entry says: a copied shipped file keeps ``name: one_segment`` inside, and
    logs, diagnostics and reports would otherwise call every lab's robot
    ``one_segment``.  A shipped robot keeps its name.
    """
    if _looks_like_path(name_or_path):
        path = Path(name_or_path).expanduser()
        if not path.is_file():
            raise ConfigError([(str(path), 'no such robot file; shipped robots: '
                                + (', '.join(shipped_robot_names()) or '(none found)'))],
                              str(path))
    else:
        path = find_shipped(str(name_or_path))
    try:
        with open(path, encoding='utf-8') as stream:   # a named stream: marks show the file
            data = yaml.load(stream, Loader=_UniqueKeyLoader)  # noqa: S506 - SafeLoader subclass
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError([(str(path), f'cannot read file: {exc}')], str(path)) from exc
    except yaml.YAMLError as exc:
        raise ConfigError([(str(path), f'YAML syntax error: {exc}')], str(path)) from exc
    cfg = robot_from_dict(data, source=str(path))
    if _looks_like_path(name_or_path) and cfg.name != path.stem:
        cfg = dataclasses.replace(cfg, name=path.stem)   # named by its file (docstring)
    return cfg
