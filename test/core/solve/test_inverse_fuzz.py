"""Seeded fuzz test of the inverse problem (issue 7): hostile targets, cold and warm along a walk.

Targets: reachable (forward solves of random in-limit pressures), perturbed,
far away, behind the base, huge and tiny, nearly opposite and non-unit
z-axes, payloads 0 to 0.1 kg.  Each is solved cold and warm-started along a
walk.  Asserted: finite in-limit pressures; reachable targets reported
reachable and reproduced to 1e-6 m and 1e-6 rad; the reported errors equal
those of a forward solve of the returned pressures; cold and warm answers
equal (1 Pa) for reachable targets; for unreachable ones no answer worse
than the corner and seed pressures it could have tried (three segments: no
corners, the seeds only).  One, two and three segments (the three-segment
robot buckles under 13 to 20 g upright: payloads up to 10 g).  Fixed seed,
modest counts: the run time is bounded (about 30 s on a loaded 2-core machine).
"""

import numpy as np
import pytest

from bellow_ancf_ros.core import solve_forward, solve_inverse
from bellow_ancf_ros.core import InverseStatus, TipLoad, precompute_corners
from bellow_ancf_ros.core.solve import MAX_CORNERS, MAX_TARGET_LENGTHS

SEED = 20261201


def _unit(v):
    return v / np.linalg.norm(v)


def _cost(model, fw, position, z_axis):
    """The documented objective |O|^2 (eq. 28, positions scaled by the robot length)."""
    c = float(np.sum(((fw.position - position) / model.length_scale) ** 2))
    if z_axis is not None:
        c += float(np.sum((fw.z_axis - z_axis) ** 2))
    return c


def _targets(model, rng, payloads, n_reachable):
    """``(kind, position, z_axis, payload, reachable)`` of a mixed, hostile set of targets.

    Reachable targets take any of the ``payloads``; the far ones only the first and last (each
    payload of an unreachable target costs forward solves at all corners of the pressure box).
    """
    multi = model.cfg.n_segments >= 2
    lo, hi = model.cfg.p_min, model.cfg.p_max
    out = []
    reach = []
    while len(reach) < n_reachable:
        m = float(rng.choice(payloads))
        fw = solve_forward(model, rng.uniform(lo, hi, model.A), m)
        if fw.success:
            reach.append((fw.position.copy(), fw.z_axis.copy() if multi else None, m))
    for k, (p, z, m) in enumerate(reach):
        out.append(("reachable", p, z, m, True))
        if multi and k % 2 == 0:  # the same pose, the axis given at an absurd length
            out.append(("non-unit z", p, z * 10.0 ** rng.choice([-300, -13, 200]), m, True))
    p, z, m = reach[0]
    out.append(
        (
            "perturbed",
            p + rng.normal(0, 5e-3, 3),
            None if z is None else _unit(z + rng.normal(0, 0.1, 3)),
            m,
            None,
        )
    )
    direction = _unit(rng.normal(size=3))
    out.append(
        (
            "far",
            direction * rng.uniform(0.5, 3.0),
            None if not multi else _unit(rng.normal(size=3)),
            float(rng.choice(payloads[:: len(payloads) - 1])),
            False,
        )
    )
    out.append(
        (
            "behind",
            np.array(
                [rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), rng.uniform(-0.5, -0.05)]
            ),
            None if not multi else np.array([0.0, 0.0, 1.0]),
            float(rng.choice(payloads[:: len(payloads) - 1])),
            False,
        )
    )
    out.append(
        (
            "huge",
            direction * 0.9 * MAX_TARGET_LENGTHS * model.length_scale,
            None if not multi else direction,
            float(rng.choice(payloads[:: len(payloads) - 1])),
            False,
        )
    )
    out.append(
        (
            "tiny",
            np.array([1e-300, -1e-300, 0.0]),
            None if not multi else np.array([0.0, 1e-300, 1.0]),
            float(rng.choice(payloads[:: len(payloads) - 1])),
            False,
        )
    )
    if multi:
        p, z, m = reach[1]
        out.append(("opposite z", p, _unit(-z + rng.normal(0, 1e-3, 3)), m, False))
    return out


class _Corners:
    """Forward solutions at the corners of the pressure box, per payload.

    All 2**A corners are taken from the inverse's own cache (public forward solves, made once
    per payload); every 16th is checked against a fresh forward solve here, and the count of
    stable corners against the box.
    """

    def __init__(self, model):
        self.model = model
        self.cache = {}

    def __call__(self, payload):
        if 2**self.model.A > MAX_CORNERS:
            return []  # the inverse tries no corners either
        if payload not in self.cache:
            precompute_corners(self.model, payload)
            entry = self.model.cached("corner_solutions", lambda m: {})[TipLoad(payload)]
            assert entry["next"] == 2**self.model.A
            sols = [fw for _, fw in entry["items"]]
            for fw in sols[::16]:
                fresh = solve_forward(self.model, fw.pressures_pa, payload)
                np.testing.assert_allclose(fresh.position, fw.position, rtol=0, atol=1e-12)
            self.cache[payload] = sols
        return self.cache[payload]


def _check(model, inv, position, z_axis, payload, reachable, seeds, corners):
    cfg = model.cfg
    p = inv.pressures_pa
    assert np.all(np.isfinite(p)) and np.all(p >= cfg.p_min) and np.all(p <= cfg.p_max)
    assert inv.converged, inv.message
    # the reported errors are those of a forward solve of the returned pressures
    fw = solve_forward(model, p, payload)
    assert fw.converged, fw.message
    dist = max(1.0, float(np.linalg.norm(position)))
    assert abs(inv.position_error_m - np.linalg.norm(fw.position - position)) <= 1e-9 * dist
    if z_axis is not None:
        zt = _unit(z_axis / np.max(np.abs(z_axis)))
        ang = np.arctan2(np.linalg.norm(np.cross(fw.z_axis, zt)), fw.z_axis @ zt)
        assert abs(inv.angle_error_rad - ang) <= 1e-8
    else:
        zt = None
    if reachable:
        assert inv.reachable and inv.status == InverseStatus.REACHED, inv.message
        assert inv.position_error_m <= 1e-6 and (zt is None or inv.angle_error_rad <= 1e-6)
    if reachable is False:
        assert not inv.reachable and not inv.success
    if not inv.reachable:
        # no answer worse than the corner and seed pressures it could have tried
        mine = _cost(model, fw, position, zt)
        tried = [solve_forward(model, s, payload) for s in seeds] + corners(payload)
        best = min(_cost(model, t, position, zt) for t in tried if t.converged)
        assert mine <= best * (1 + 1e-9) + 1e-12, (mine, best, inv.message)


@pytest.mark.parametrize("name, n_reachable",
                         [("one_segment", 6), ("two_segment", 5), ("three_segment", 4)])
def test_inverse_fuzz(name, n_reachable, one, two, three):
    model = {"one_segment": one, "two_segment": two, "three_segment": three}[name]
    rng = np.random.default_rng(SEED)
    heaviest = 0.01 if name == "three_segment" else 0.1
    payloads = [0.0, float(rng.uniform(0.0, heaviest)), heaviest]
    corners = _Corners(model)
    cfg = model.cfg
    vent, mid = np.zeros(model.A), np.full(model.A, 0.5 * (cfg.p_min + cfg.p_max))
    targets = _targets(model, rng, payloads, n_reachable)
    order = rng.permutation(len(targets))  # the walk visits the targets in random order
    prev = None
    for i in order:
        kind, position, z_axis, payload, reachable = targets[i]
        cold = solve_inverse(model, position, z_axis, payload_kg=payload)
        warm = solve_inverse(model, position, z_axis, payload_kg=payload, warm_start=prev)
        where = f"{name} {kind} target {position} z {z_axis} payload {payload}"
        for label, inv, seeds in (
            ("cold", cold, [vent, mid]),
            ("warm", warm, [vent, mid] + ([] if prev is None else [prev.pressures_pa])),
        ):
            try:
                _check(model, inv, position, z_axis, payload, reachable, seeds, corners)
            except AssertionError as exc:
                raise AssertionError(f"{label}, {where}: {exc}") from exc
        if cold.reachable or warm.reachable:
            assert cold.reachable and warm.reachable, where
            np.testing.assert_allclose(
                warm.pressures_pa, cold.pressures_pa, rtol=0, atol=1.0, err_msg=where
            )
        prev = warm
