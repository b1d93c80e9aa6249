"""Model studies (core/studies.py): convergence, workspace, PCC comparison, tracking."""

import numpy as np
import pytest

from bellow_ancf_ros.core import RobotModel, load_robot, solve_forward, studies, tip_compliance


def test_nodes_on_plates(one_cfg):
    assert [n for n in range(1, 13) if studies.nodes_on_plates(one_cfg, n)] == [3, 6, 9, 12]
    quarter = one_cfg.replace(segments=(one_cfg.segments[0].__class__(
        **{**one_cfg.segments[0].__dict__, 'plate_fractions': (0.25, 0.5, 0.75)}),))
    assert [n for n in range(1, 13) if studies.nodes_on_plates(quarter, n)] == [4, 8, 12]


def test_the_papers_18_one_segment_schemes(one_cfg):
    schemes = studies.workspace_schemes(one_cfg)
    assert len(schemes) == 18
    assert len({s.name for s in schemes}) == 18
    assert sum(len(s.swept) == 1 for s in schemes) == 12
    assert sum(len(s.swept) == 2 for s in schemes) == 6
    for s in schemes:
        assert set(s.swept) | set(s.fixed) == {0, 1, 2}
        assert all(v in (one_cfg.p_min, one_cfg.p_max) for v in s.fixed.values())
        P = s.pressures(one_cfg, 5)
        assert P.shape == (5, 3)
        swept = P[:, list(s.swept)]
        assert np.all(swept[0] == one_cfg.p_min) and np.all(swept[-1] == one_cfg.p_max)


def test_the_papers_four_two_segment_schemes(two_cfg):
    schemes = studies.workspace_schemes(two_cfg)
    # s11+s21, s11+s22, s11+s21+s22, s11+s22+s23 (0-based: 0, 3, 4, 5), the others at 0 kPa
    assert [s.swept for s in schemes] == [(0, 3), (0, 4), (0, 3, 4), (0, 4, 5)]
    assert all(set(s.fixed.values()) == {0.0} for s in schemes)


def test_convergence_recommends_a_multiple_of_three_for_the_default_plates(one_cfg):
    res = studies.convergence_study(one_cfg, counts=range(1, 7), reference_n=24, repeats=1)
    err = {r.n: r.error_m for r in res.rows}
    print({n: None if e is None else round(e * 1e3, 6) for n, e in err.items()},
          res.recommended, res.reason)
    assert res.recommended is not None and res.recommended % 3 == 0
    assert res.recommended == 3
    assert err[1] is None and err[2] is None  # one or two elements cannot carry two plates
    assert all('smallest count that works is 3' in r.refused for r in res.rows[:2])
    # plates on nodes converge much better than plates inside elements
    assert err[3] < 0.1 * err[4] and err[6] < 0.1 * err[5]
    assert err[6] < 1e-6
    assert all(r.time_s > 0 for r in res.rows[2:])
    d = res.to_dict()
    assert d['recommended_n'] == 3 and len(d['rows']) == 6


def test_two_segment_convergence_recommends_six(two_cfg):
    actuations = {'paper': np.r_[two_cfg.p_max, np.zeros(5)],
                  'lo': np.r_[two_cfg.p_max, np.full(5, two_cfg.p_min)]}
    res = studies.convergence_study(two_cfg, counts=(3, 4, 6), reference_n=18, repeats=1,
                                    actuations=actuations)
    print([(r.n, r.error_m) for r in res.rows])
    assert res.recommended == 6
    assert res.rows[0].error_m > res.threshold_m  # n = 3 is not enough for two segments


def test_workspace_study_one_segment(one_cfg):
    progress = []
    res = studies.workspace_study(one_cfg, payloads_kg=(0.0, 0.1), n_points=4,
                                  progress=lambda d, t, s: progress.append((d, t)))
    rows = res['rows']
    assert len(rows) == 2 * 18 * 4
    assert all(r['converged'] and r['stable'] for r in rows)
    assert progress[-1][0] == progress[-1][1] == 36
    P0 = np.array([r['position_m'] for r in rows if r['payload_kg'] == 0.0])
    P1 = np.array([r['position_m'] for r in rows if r['payload_kg'] == 0.1])
    # actuator 1 inflated, the others at p_min: the tip bends away from actuator 1 (-x)
    a1 = [r for r in rows if r['payload_kg'] == 0.0 and r['scheme'] == 0]
    assert a1[-1]['position_m'][0] < -0.015 and abs(a1[-1]['position_m'][1]) < 1e-9
    # symmetric about the x-axis
    assert np.max(P0[:, 1]) == pytest.approx(-np.min(P0[:, 1]), rel=1e-6)
    # the payload lowers the workspace
    assert np.max(P1[:, 2]) < np.max(P0[:, 2]) and np.min(P1[:, 2]) < np.min(P0[:, 2])


def test_compare_pcc_agrees_without_forces_and_disagrees_under_payload(one_cfg):
    nog = studies.compare_pcc(one_cfg, payloads_kg=(0.0,), n_points=3, gravity=False, schemes=[])
    assert nog['summary'][0]['category'] == 'elongation'
    assert nog['summary'][0]['max_m'] < 1e-9
    res = studies.compare_pcc(one_cfg, payloads_kg=(0.0, 0.1), n_points=3,
                              schemes=studies.workspace_schemes(one_cfg)[:2])
    s = {(r['payload_kg'], r['category']): r for r in res['summary']}
    assert s[(0.1, 'elongation')]['max_m'] > 0.5e-3
    assert s[(0.1, 'elongation')]['max_m'] > 2 * s[(0.0, 'elongation')]['max_m']
    assert s[(0.1, 'elongation')]['mean_dz_m'] < 0  # the payload compresses the ANCF robot
    assert s[(0.0, 'bending')]['points'] == 6


def test_tracking_one_segment_default_trajectory_is_reachable(one_cfg):
    res = studies.tracking_study(RobotModel(one_cfg), 'planar_circle', n_points=12,
                                 payload_kg=0.05)
    st = res.stats()
    print(st)
    assert st['reachable_fraction'] == 1.0 and st['success_fraction'] == 1.0
    assert st['position_max_m'] < 1e-9
    assert st['angle_rms_rad'] is None
    assert res.pressures_pa.shape == (12, 3)
    assert np.all((res.pressures_pa >= one_cfg.p_min) & (res.pressures_pa <= one_cfg.p_max))
    assert 0 < st['solve_time_median_s'] <= st['solve_time_p99_s']
    assert res.times_s[1] == pytest.approx(res.params['period'] / 12)


def test_tracking_two_segment_bending_circle_holds_the_angle(two_cfg):
    res = studies.tracking_study(RobotModel(two_cfg), 'bending_circle', n_points=6)
    st = res.stats()
    assert st['reachable_fraction'] == 1.0
    assert st['position_max_m'] < 1e-9 and st['angle_max_rad'] < 1e-8
    tilt = np.degrees(np.arccos(res.predicted_z_axes[:, 2]))
    assert np.allclose(tilt, res.params['bending_angle_deg'], atol=1e-6)


def test_pcc_feedforward_misses_under_payload(one_cfg):
    res = studies.tracking_study(RobotModel(one_cfg), 'planar_circle', n_points=6, payload_kg=0.1,
                                 controller='pcc')
    st = res.stats()
    assert st['reachable_fraction'] == 1.0  # reachable for the PCC model ...
    assert st['position_rms_m'] > 0.5e-3    # ... but the ANCF model predicts a miss


def test_three_segment_schemes_move_every_segment():
    cfg = load_robot('three_segment')
    schemes = studies.workspace_schemes(cfg)
    # the paper's four patterns of segment 2, repeated in segment 3 (0-based 3.. and 6..)
    assert [s.swept for s in schemes] == [(0, 3, 6), (0, 4, 7), (0, 3, 4, 6, 7),
                                          (0, 4, 5, 7, 8)]
    for s in schemes:
        assert {i // 3 for i in s.swept} == {0, 1, 2}
        assert set(s.fixed) == set(range(9)) - set(s.swept)


def test_compare_pcc_says_when_no_point_is_usable():
    """Three segments buckle upright under 0.1 kg: the summary says so instead of dropping it."""
    cfg = load_robot('three_segment')
    res = studies.compare_pcc(cfg, payloads_kg=(0.0, 0.1), n_points=3,
                              schemes=studies.workspace_schemes(cfg)[:1])
    s = {(r['payload_kg'], r['category']): r for r in res['summary']}
    assert len(s) == 4
    assert s[(0.0, 'elongation')]['usable'] == s[(0.0, 'elongation')]['points'] == 3
    heavy = s[(0.1, 'elongation')]
    assert heavy['points'] == 3 and heavy['usable'] == 0 and heavy['rms_m'] is None


def test_stiffness_study_vertical_stiffness_against_pressure_and_payload(one_cfg):
    res = studies.stiffness_study(one_cfg, payloads_kg=(0.0, 0.05), n_levels=3)
    rows = res['rows']
    assert len(rows) == 6 and all(r['usable'] for r in rows)
    mid = 0.5 * (one_cfg.p_min + one_cfg.p_max)
    assert [r['pressure_pa'] for r in rows[:3]] == [one_cfg.p_min, mid, one_cfg.p_max]
    model = RobotModel(one_cfg)
    for r in rows:
        fw = solve_forward(model, np.full(3, r['pressure_pa']), r['payload_kg'])
        C = tip_compliance(fw).translational_m_per_n
        assert r['vertical_n_per_m'] == pytest.approx(1 / C[2, 2], rel=1e-9)
        # a symmetric robot under equal pressures: alike in x and y, far stiffer vertically
        assert r['lateral_x_n_per_m'] == pytest.approx(r['lateral_y_n_per_m'], rel=1e-6)
        assert r['vertical_n_per_m'] > 10 * r['lateral_x_n_per_m']


def test_stiffness_along_a_trajectory(one):
    res = studies.stiffness_along_trajectory(one, 'planar_circle', n_points=6)
    assert res['usable'].all() and len(res['times_s']) == 6
    # the circle is symmetric about the axis: the vertical stiffness varies little along it
    v = res['vertical_n_per_m']
    assert np.all(np.isfinite(v)) and (v.max() - v.min()) < 0.05 * v.mean()
