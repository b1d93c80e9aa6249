"""Reference trajectories of the paper (section VI.C), pure numpy.

One segment (position targets): ``space_spiral``, ``space_rose``,
``planar_circle``, ``planar_spiral``, ``planar_rose``.  Two or more segments
(position + end-effector z-axis targets): the same five curves with a
vertical z-axis (bending angle 0, as in the paper's Fig. 10), and
``bending_circle``: a circle along which the end-effector z-axis keeps a
constant *bending angle* ``beta`` to the base z-axis (paper: 0, 10 or 20
degrees), tilted radially outward, i.e. in the vertical plane through the
circle's centre and the point: ``z = (sin(beta) cos(phi), sin(beta) sin(phi),
cos(beta))``.  The other curves pass through the centre, where "outward"
is undefined, so they only take a bending angle of 0.

Every curve is closed: with ``s = (t mod period) / period`` in ``[0, 1)`` it
starts and ends at the same point with the same tangent, so a publisher can
loop it.  Shapes (``R`` radius, ``H`` height amplitude, ``k`` petals
parameter, ``n`` turns, ``phi = 2 pi s``, positions relative to ``center``):

* ``planar_circle``:  ``(R cos phi, R sin phi, 0)``
* ``planar_spiral``:  radius ``rho = R (1 - cos phi) / 2`` (out from the
  centre to ``R`` and back), angle ``psi = n phi``: ``(rho cos psi, rho sin psi, 0)``
* ``planar_rose``:    ``rho = R cos(k phi)``: ``(rho cos phi, rho sin phi, 0)``
  (``2k`` petals for even ``k``, ``k`` for odd)
* ``space_spiral`` / ``space_rose``: the planar curve lifted onto the dome
  ``z = H (1 - (rho/R)^2)``: highest at the centre, at ``center`` height on
  the rim, the shape of the robot's workspace (its height range narrows as
  the tip moves outward).

Defaults come from the robot description (no solve needed): the straight
robot's height at ``p_min`` and ``p_max`` (stage 1, eq. 24; segment lengths
plus connectors plus tool) gives the stroke ``[z_lo, z_hi]``, and a
constant-curvature estimate of the lateral reach (each segment bent by the
full length difference of its actuators) gives ``reach``:

* ``center = (0, 0, z_lo + 0.45 (z_hi - z_lo))``
* ``radius = 0.40 reach``, ``height_amplitude = 0.20 (z_hi - z_lo)``
* ``bending_circle``: height ``z_lo + 0.375 (z_hi - z_lo)``, bending angle
  10 deg, and a radius that grows with the bending angle,
  ``radius = (0.40 + 0.02 beta/deg) reach``: a tip tilted outward by
  ``beta`` sits where a robot bent into one arc puts it, further out than an
  S-bent robot with a vertical tip.  With one circle for all angles the
  inverse solution of the default robot runs into a pressure limit at 0 or
  20 deg; with this rule every pressure stays >= 20 kPa inside its limits.
* ``period``: path length over a quasi-static tip speed of 2 mm/s (the
  paper reports dynamic effects above 2.67 mm/s), rounded up to 5 s.

For the default robots this gives (one segment) a 10.4 mm circle at 99.0 mm
height and (two segments) a 17.9 mm circle at 211.1 mm and bending circles
at 209.0 mm of radius 17.9, 26.8 and 35.7 mm for 0, 10 and 20 deg;
``test/test_trajectories.py`` checks with the inverse solver that every
default trajectory, and a 15 % larger copy of it, is reachable, and that
the pressures of the defaults keep a margin to the limits.
"""

from __future__ import annotations

import math
import os
from functools import lru_cache
from typing import Any

import numpy as np

from ..geometry import rotation_between, rotation_from_vector
from ..model import RobotConfig, Stage1, load_robot

__all__ = [
    'lead_in',
    'spin_down',
    'spin_up',
    'trajectory_target',
    'MULTI_SEGMENT_TRAJECTORIES',
    'ONE_SEGMENT_TRAJECTORIES',
    'PAPER_BENDING_ANGLES_DEG',
    'QUASI_STATIC_SPEED',
    'TRAJECTORY_NAMES',
    'default_parameters',
    'trajectory',
    'trajectory_parameters',
    'workspace_estimate',
]

ONE_SEGMENT_TRAJECTORIES = ('space_spiral', 'space_rose', 'planar_circle', 'planar_spiral',
                            'planar_rose')
MULTI_SEGMENT_TRAJECTORIES = ONE_SEGMENT_TRAJECTORIES + ('bending_circle',)
TRAJECTORY_NAMES = MULTI_SEGMENT_TRAJECTORIES
PAPER_BENDING_ANGLES_DEG = (0.0, 10.0, 20.0)

#: Tip speed [m/s] used to derive the default period (quasi-static motion).
QUASI_STATIC_SPEED = 2e-3

_CIRCLES = ('planar_circle', 'bending_circle')
_SPIRALS = ('space_spiral', 'planar_spiral')
_ROSES = ('space_rose', 'planar_rose')
_SPACE = ('space_spiral', 'space_rose')

_PARAMS = ('center', 'height', 'radius', 'height_amplitude', 'period', 'turns', 'petals',
           'bending_angle_deg')


# ------------------------------------------------------------------- config
@lru_cache(maxsize=16)
def _load_cached(name: str) -> RobotConfig:
    return load_robot(name)


def _config(config: Any) -> RobotConfig:
    if isinstance(config, RobotConfig):
        return config
    if isinstance(config, (str, os.PathLike)):
        return _load_cached(os.fspath(config))
    raise TypeError('config must be a RobotConfig, a robot name or a path, '
                    f'got {type(config).__name__}')


def workspace_estimate(config: Any = 'one_segment') -> dict:
    """Cheap workspace estimate of a robot (no equilibrium solve).

    Returns ``{'z_lo', 'z_hi', 'reach'}`` [m]: the straight robot's
    end-effector height at ``p_min`` and ``p_max`` on every actuator (stage 1
    only, gravity ignored) and a constant-curvature estimate of the largest
    lateral tip displacement.
    """
    cfg = _config(config)
    st = Stage1.from_config(cfg)
    lam_lo, lam_hi = float(st.lam_min), float(st.lam_max)
    lam_mid = float(st.stretch(0.5 * (cfg.p_min + cfg.p_max)))
    conn = sum(s.connector_height for s in cfg.segments) + cfg.tool_length
    n = cfg.n_segments
    z_lo = n * cfg.l0 * lam_lo + conn
    z_hi = n * cfg.l0 * lam_hi + conn
    reach = 0.0
    for seg in cfg.segments:
        spread = seg.pitch_radius * (1.0 - math.cos(2.0 * math.pi / seg.n_actuators))
        theta = cfg.l0 * (lam_hi - lam_lo) / spread
        length = cfg.l0 * lam_mid
        reach += length * (1.0 - math.cos(theta)) / theta if theta > 1e-12 else 0.0
    return {'z_lo': z_lo, 'z_hi': z_hi, 'reach': reach}


def _path_length(name: str, p: dict) -> float:
    s = np.linspace(0.0, 1.0, 2001)
    pos = _shape(name, s, p)
    return float(np.sum(np.linalg.norm(np.diff(pos, axis=0), axis=1)))


def default_parameters(name: str, config: Any = 'one_segment',
                       bending_angle_deg: float | None = None) -> dict:
    """The default parameters of trajectory ``name`` for a robot.

    Keys: ``center`` (3-tuple, m), ``radius`` (m), ``height_amplitude`` (m),
    ``period`` (s), ``turns``, ``petals``, and for robots with two or more
    segments ``bending_angle_deg``.
    """
    cfg = _config(config)
    _check_name(name, cfg)
    params_beta = None if bending_angle_deg is None else _check_beta(bending_angle_deg)
    ws = workspace_estimate(cfg)
    stroke = ws['z_hi'] - ws['z_lo']
    if name == 'bending_circle':
        beta = params_beta if params_beta is not None else 10.0
        center = (0.0, 0.0, ws['z_lo'] + 0.375 * stroke)
        radius = (0.40 + 0.02 * beta) * ws['reach']
    else:
        center = (0.0, 0.0, ws['z_lo'] + 0.45 * stroke)
        radius = 0.40 * ws['reach']
    p = {
        'center': center,
        'radius': radius,
        'height_amplitude': 0.20 * stroke,
        'turns': 3,
        'petals': 2,
    }
    if cfg.n_segments >= 2:
        p['bending_angle_deg'] = beta if name == 'bending_circle' else 0.0
    length = _path_length(name, p)
    p['period'] = 5.0 * math.ceil(length / QUASI_STATIC_SPEED / 5.0)
    return p


# ------------------------------------------------------------------- curves
def _check_name(name: str, cfg: RobotConfig) -> None:
    if name not in TRAJECTORY_NAMES:
        raise ValueError(f'unknown trajectory {name!r}; known: {", ".join(TRAJECTORY_NAMES)}')
    if name == 'bending_circle' and cfg.n_segments < 2:
        raise ValueError("'bending_circle' needs a robot with two or more segments "
                         '(a one-segment robot cannot hold a bending angle at a given position)')


def _shape(name: str, s: np.ndarray, p: dict) -> np.ndarray:
    """Positions relative to the centre at normalised times ``s`` (N,) -> (N, 3)."""
    R = float(p['radius'])
    phi = 2.0 * np.pi * s
    z = np.zeros_like(s)
    if name in _CIRCLES:
        rho, ang = np.full_like(s, R), phi
    elif name in _SPIRALS:
        rho, ang = 0.5 * R * (1.0 - np.cos(phi)), int(p['turns']) * phi
    else:  # roses
        rho, ang = R * np.cos(int(p['petals']) * phi), phi
    if name in _SPACE:
        z = float(p['height_amplitude']) * (1.0 - (rho / R) ** 2)
    return np.column_stack([rho * np.cos(ang), rho * np.sin(ang), z])


def _check_beta(value: Any) -> float:
    b = float(value)
    if not (math.isfinite(b) and 0.0 <= b < 90.0):
        raise ValueError(f'bending_angle_deg must be in [0, 90), got {value}')
    return b


def _merge(name: str, cfg: RobotConfig, params: dict) -> dict:
    unknown = sorted(set(params) - set(_PARAMS))
    if unknown:
        raise ValueError(f'unknown trajectory parameter(s) {unknown}; known: {list(_PARAMS)}')
    beta = params.get('bending_angle_deg') if cfg.n_segments >= 2 else None
    p = default_parameters(name, cfg, bending_angle_deg=beta)
    for key, val in params.items():
        if val is not None and key != 'height':
            p[key] = val
    if params.get('height') is not None:
        c = list(np.asarray(p['center'], dtype=float).ravel())
        if len(c) == 3:
            c[2] = float(params['height'])
        p['center'] = tuple(c)
    center = np.asarray(p['center'], dtype=float).ravel()
    if center.size != 3 or not np.all(np.isfinite(center)):
        raise ValueError(f'center must be 3 finite numbers [m], got {p["center"]}')
    p['center'] = tuple(center)
    for key in ('radius', 'period'):
        v = float(p[key])
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f'{key} must be a positive finite number, got {p[key]}')
        p[key] = v
    v = float(p['height_amplitude'])
    if not math.isfinite(v):
        raise ValueError(f'height_amplitude must be finite, got {p["height_amplitude"]}')
    p['height_amplitude'] = v
    for key in ('turns', 'petals'):
        v = p[key]
        if isinstance(v, bool) or int(v) != v or int(v) < 1:
            raise ValueError(f'{key} must be a positive integer, got {v}')
        p[key] = int(v)
    if cfg.n_segments >= 2:
        b = _check_beta(p.get('bending_angle_deg', 0.0))
        if b != 0.0 and name != 'bending_circle':
            raise ValueError(f"{name!r} keeps the end-effector z-axis vertical (bending angle 0); "
                             "use 'bending_circle' for a constant non-zero bending angle")
        p['bending_angle_deg'] = b
    elif params.get('bending_angle_deg') not in (None, 0, 0.0):
        raise ValueError('bending_angle_deg needs a robot with two or more segments '
                         '(a one-segment robot is controlled in position only)')
    else:
        p.pop('bending_angle_deg', None)
    return p


def trajectory_parameters(name: str, config: Any = 'one_segment', **params: Any) -> dict:
    """Return the parameters :func:`trajectory` uses for ``name`` with ``params``.

    These are the defaults (for the given bending angle) with the overrides
    applied and ``height`` folded into ``center``.  Raises ``ValueError`` like
    :func:`trajectory`.
    """
    cfg = _config(config)
    _check_name(name, cfg)
    return _merge(name, cfg, params)


def trajectory(name: str, t: Any, config: Any = 'one_segment', **params: Any):
    """Target poses of trajectory ``name`` at times ``t`` [s].

    Parameters
    ----------
    name : one of :data:`TRAJECTORY_NAMES`.
    t : scalar or array of times [s]; the curve repeats with ``period``.
    config : :class:`RobotConfig`, shipped robot name or robot file path.
    **params : overrides of :func:`default_parameters`: ``center`` (x, y, z)
        [m], ``height`` (z of the centre) [m], ``radius`` [m],
        ``height_amplitude`` [m] (space curves), ``period`` [s], ``turns``
        (spirals), ``petals`` (roses), ``bending_angle_deg`` (two or more
        segments; circles only when non-zero).

    Returns
    -------
    positions : (N, 3) end-effector positions [m] in the base frame.
    z_axes : (N, 3) unit end-effector z-axes for robots with two or more
        segments, else None.
    """
    cfg = _config(config)
    _check_name(name, cfg)
    return _poses(name, cfg, _merge(name, cfg, params), t)


def _poses(name: str, cfg: RobotConfig, p: dict, t: Any):
    """:func:`trajectory` with its parameters merged and checked (``p``, :func:`_merge`)."""
    tt = np.atleast_1d(np.asarray(t, dtype=float)).ravel()
    if not np.all(np.isfinite(tt)):
        raise ValueError('times must be finite')
    s = np.mod(tt, p['period']) / p['period']
    rel = _shape(name, s, p)
    pos = rel + np.asarray(p['center'])
    if cfg.n_segments < 2:
        return pos, None
    beta = math.radians(p['bending_angle_deg'])
    # radially outward direction; on a circle the radius never vanishes
    phi = np.arctan2(rel[:, 1], rel[:, 0])
    z_axes = np.column_stack([
        math.sin(beta) * np.cos(phi),
        math.sin(beta) * np.sin(phi),
        np.full_like(phi, math.cos(beta)),
    ])
    return pos, z_axes


def trajectory_target(name: str, config: Any = 'one_segment', **params: Any):
    """Trajectory ``name`` as a function of time: ``target(t) -> (position (3,), z-axis or None)``.

    The parameters are checked once, here (``ValueError`` as
    :func:`trajectory`); the z-axis is None for one segment.  What a
    closed-loop simulation (:class:`~bellow_ancf_ros.core.loop.LoopSimulation`)
    is fed.
    """
    cfg = _config(config)
    _check_name(name, cfg)
    p = _merge(name, cfg, params)   # once: the defaults cost a stage-1 set-up (about 1 ms)

    def target(t: float):
        pos, z = _poses(name, cfg, p, t)
        return pos[0], None if z is None else z[0]
    return target


def lead_in(start_position, start_z, end_position, end_z, fraction):
    """A pose on the way from where the robot is to where a trajectory starts.

    Minimum-jerk timing ``s = 10 f^3 - 15 f^4 + 6 f^5`` of ``fraction`` ``f``
    in [0, 1] (zero velocity and acceleration at both ends), a straight line
    for the position, and for the z-axis (None: one segment) a rotation
    about ``start_z x end_z`` by ``s`` times their angle.  Returns
    ``(position (3,), z_axis (3,) or None)``.
    """
    f = min(max(float(fraction), 0.0), 1.0)
    s = f ** 3 * (10.0 - 15.0 * f + 6.0 * f * f)
    p0, p1 = np.asarray(start_position, dtype=float), np.asarray(end_position, dtype=float)
    pos = p0 + s * (p1 - p0)
    if start_z is None or end_z is None:
        return pos, None
    z0 = np.asarray(start_z, dtype=float) / np.linalg.norm(start_z)
    return pos, rotation_from_vector(s * rotation_between(z0, end_z)) @ z0


def spin_up(t: float, duration_s: float) -> float:
    """The path's time after ``t`` seconds of a start whose speed rises over ``duration_s``.

    A path that starts at full speed (a circle does) asks a robot at rest for
    a jump of velocity: a robot with a lightly damped mode rings for seconds
    after it (docs/dynamics.md; ``trajectory_publisher`` ``spin_up_s``).  The
    speed factor rises from 0 to 1 with minimum-jerk timing
    ``sigma = 10 f^3 - 15 f^4 + 6 f^5`` of ``f = t / duration_s``, so the
    path's speed, acceleration and jerk start at zero; the path time is its
    integral, ``duration_s (5 f^4 / 2 - 3 f^5 + f^6)``, and from the end of
    the spin-up on ``t - duration_s / 2`` (the path at full speed, half the
    spin-up behind a path that started at full speed).  ``duration_s`` 0:
    ``t`` itself.
    """
    t, d = float(t), float(duration_s)
    if not (math.isfinite(d) and d >= 0):
        raise ValueError(f'spin_up_s = {duration_s!r} is not allowed; allowed: a time >= 0 [s]')
    if d == 0.0 or t >= d:
        return t - d / 2
    if t <= 0.0:
        return t
    f = t / d
    return d * f ** 4 * (2.5 - 3.0 * f + f * f)


def spin_down(s: float, duration_s: float) -> float:
    """How far [path time] a path at full speed goes in ``s`` seconds while it stops.

    The mirror of :func:`spin_up`: the speed falls from full to zero over
    ``duration_s`` with minimum-jerk timing, covering half of it in path
    time (``duration_s / 2`` from then on); a path that stops so does not
    ring a robot's mode as a jump to rest would.
    """
    d = float(duration_s)
    if not (math.isfinite(d) and d >= 0):
        raise ValueError(f'spin_up_s = {duration_s!r} is not allowed; allowed: a time >= 0 [s]')
    s = min(max(float(s), 0.0), d)
    return d / 2 - spin_up(d - s, d) if d > 0 else 0.0
