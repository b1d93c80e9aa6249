"""Scalar parameters of a robot file addressed by key (what ``calibrate --fit`` takes).

A key is the dotted path of a number in the robot file's schema
(:meth:`RobotConfig.to_dict`, file units), the form :class:`ConfigError`
uses: ``actuator.d_a_mm``, ``segments[0].pitch_radius_mm``,
``actuator.stiffness_coeffs_n_per_m[1]``, ``model.tool_length_mm``,
``payload_kg``.  ``segments[*].top_plate_mass_kg`` ties one value to every
segment that has the key.  The virtual key ``stiffness_scale`` (nominal 1)
multiplies every coefficient of the stiffness polynomial ``k(lam)``;
``mass_scale`` (nominal 1) every mass of the robot (the actuators' linear
density, the plates and connectors; not the payload).

Counts (``n_actuators``, ``n_elements``), the name, the pressure limits and
gravity are not parameters.  No ROS import.
"""

from __future__ import annotations

import copy
import re
from typing import Any, Sequence

__all__ = ['MASS_SCALE', 'ParameterKeyError', 'STIFFNESS_SCALE', 'default_keys', 'parameter_keys',
           'get_value', 'with_values', 'key_scale', 'check_keys']

STIFFNESS_SCALE = 'stiffness_scale'
MASS_SCALE = 'mass_scale'
_VIRTUAL = (STIFFNESS_SCALE, MASS_SCALE)
#: The masses ``mass_scale`` multiplies: the actuators' and each segment's.
_ACTUATOR_MASSES = ('linear_density_kg_per_m',)
_SEGMENT_MASSES = ('constraint_plate_mass_kg', 'top_plate_mass_kg', 'connector_mass_kg')
_NOT_PARAMETERS = ('name', 'n_actuators', 'n_elements', 'pressure_limits', 'gravity_m_per_s2')
_PART = re.compile(r'^([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+|\*)\])?$')


class ParameterKeyError(ValueError):
    """A key that names no fittable scalar of the robot file."""


def default_keys(d: dict) -> list[str]:
    """Default fit: every segment's pitch radius, ``D_a``, ``D_eff``, the stiffness scale."""
    keys = [f'segments[{j}].pitch_radius_mm' for j in range(len(d['segments']))]
    return keys + ['actuator.d_a_mm', 'actuator.d_eff_mm', STIFFNESS_SCALE]


def parameter_keys(d: dict) -> list[str]:
    """Every fittable key of the description ``d`` (file schema)."""
    out = []

    def walk(node: Any, path: str) -> None:
        if isinstance(node, dict):
            for k, v in node.items():
                if k not in _NOT_PARAMETERS:
                    walk(v, f'{path}.{k}' if path else k)
        elif isinstance(node, list):
            for i, v in enumerate(node):
                walk(v, f'{path}[{i}]')
        elif isinstance(node, float):
            out.append(path)
    walk(d, '')
    return out + list(_VIRTUAL)


def _locations(d: dict, key: str) -> list[tuple[Any, Any]]:
    """``(container, index)`` pairs that ``key`` addresses in ``d``."""
    if not isinstance(key, str) or not key:
        raise ParameterKeyError(f'parameter key must be a non-empty string, got {key!r}')
    nodes: list[tuple[Any, Any]] = [(None, d)]
    parts = key.split('.')
    for n, part in enumerate(parts):
        m = _PART.match(part)
        if m is None or m.group(1) in _NOT_PARAMETERS:
            raise _unknown(d, key)
        name, index = m.group(1), m.group(2)
        found = []
        for _, node in nodes:
            if not isinstance(node, dict) or name not in node:
                continue
            child = node[name]
            if index is None:
                found.append((node, name))
            elif isinstance(child, list):
                idx = range(len(child)) if index == '*' else [int(index)]
                found += [(child, i) for i in idx if i < len(child)]
        if not found:
            raise _unknown(d, key)
        nodes = [(c, c[i]) for c, i in found] if n < len(parts) - 1 else found
    if any(not isinstance(c[i], float) for c, i in nodes):
        raise _unknown(d, key)
    return nodes


def _unknown(d: dict, key: str) -> ParameterKeyError:
    return ParameterKeyError(f'--fit {key!r}: not a scalar parameter of the robot file; allowed: '
                             + ', '.join(parameter_keys(d))
                             + " (and segments[*].<key> for one value on every segment)")


def check_keys(d: dict, keys: Sequence[str]) -> list[str]:
    """The keys, validated (unknown or repeated keys raise :class:`ParameterKeyError`)."""
    seen = []
    for key in keys:
        if key not in _VIRTUAL:
            _locations(d, key)
        if key in seen:
            raise ParameterKeyError(f'--fit {key!r} is given twice')
        seen.append(key)
    return seen


def get_value(d: dict, key: str) -> float:
    """Value of ``key`` in ``d`` (file units; the stiffness and mass scales of a file are 1)."""
    if key in _VIRTUAL:
        return 1.0
    container, index = _locations(d, key)[0]
    return float(container[index])


def with_values(d: dict, keys: Sequence[str], values: Sequence[float]) -> dict:
    """A deep copy of ``d`` with ``keys`` set to ``values`` (the scales multiply)."""
    out = copy.deepcopy(d)
    for key, value in zip(keys, values):
        if key == STIFFNESS_SCALE:
            act = out['actuator']
            coeffs = act['stiffness_coeffs_n_per_m']
            act['stiffness_coeffs_n_per_m'] = [float(value) * c for c in coeffs]
            continue
        if key == MASS_SCALE:
            for part, names in ([out['actuator']], _ACTUATOR_MASSES), (out['segments'],
                                                                       _SEGMENT_MASSES):
                for node in part:
                    for name in names:
                        if name in node:
                            node[name] = float(value) * node[name]
            continue
        for container, index in _locations(out, key):
            container[index] = float(value)
    return out


def key_scale(key: str, value: float) -> float:
    """Natural size of a change of ``key``: its magnitude, or a unit-based size for zero."""
    if abs(value) > 0.0:
        return abs(float(value))
    for suffix, size in (('_mm', 1.0), ('_deg', 1.0), ('_kg', 0.01), ('_m', 1e-3)):
        if key.endswith(suffix):
            return size
    return 1.0
