"""Results at the default settings do not move: values recorded from the model before issue 7.

Tip positions of forward solves and pressures of inverse solves at n = 4, 6 and 24 elements,
recorded with the code of commit 1f2d442 (before the edge-case work of issue 7).
"""

import numpy as np
import pytest

from bellow_ancf_ros.core import RobotModel, load_robot, solve_forward, solve_inverse

# (robot, n, pressures kPa, payload kg) -> tip position [m]
FORWARD = [
    (
        "one_segment",
        4,
        [150, -50, -50],
        0.1,
        [-0.023578621991727108, 1.3752187124994094e-17, 0.09237123197610281],
    ),
    (
        "one_segment",
        4,
        [60, 0, -20],
        0.0,
        [-0.007880466086938927, -0.0020640291376521976, 0.09664068635950522],
    ),
    (
        "one_segment",
        6,
        [150, -50, -50],
        0.1,
        [-0.02372770922124191, 7.332210700091058e-18, 0.09232898380316586],
    ),
    (
        "one_segment",
        6,
        [60, 0, -20],
        0.0,
        [-0.007893340252841224, -0.002067427953486305, 0.09663953106851288],
    ),
    (
        "one_segment",
        24,
        [150, -50, -50],
        0.1,
        [-0.0237286160515975, 1.653441375744898e-17, 0.09232868852027215],
    ),
    (
        "one_segment",
        24,
        [60, 0, -20],
        0.0,
        [-0.007893413378920551, -0.0020674461361022216, 0.09663952402069642],
    ),
    (
        "two_segment",
        4,
        [120, -50, -50, 120, -50, -50],
        0.0,
        [-0.09304337766680636, 1.0398720562968524e-16, 0.17747498407217174],
    ),
    (
        "two_segment",
        4,
        [90, -20, 10, -30, 60, 0],
        0.05,
        [-0.04670491533445671, 0.007928238809824484, 0.20244665169910556],
    ),
    (
        "two_segment",
        6,
        [120, -50, -50, 120, -50, -50],
        0.0,
        [-0.09331851064746711, 5.068586409990513e-17, 0.17733034963446154],
    ),
    (
        "two_segment",
        6,
        [90, -20, 10, -30, 60, 0],
        0.05,
        [-0.047085717395229015, 0.008009362414603422, 0.20234976056688844],
    ),
    (
        "two_segment",
        24,
        [120, -50, -50, 120, -50, -50],
        0.0,
        [-0.09332067511602025, -4.6038532425073545e-17, 0.17732915709484393],
    ),
    (
        "two_segment",
        24,
        [90, -20, 10, -30, 60, 0],
        0.05,
        [-0.047088774015405274, 0.00800993915486561, 0.2023489453730849],
    ),
]

# (robot, n, target position, target z-axis, payload) -> pressures [Pa]
INVERSE = [
    (
        "one_segment",
        4,
        [-0.00022048285654499103, -0.00998898594294235, 0.09840004724887767],
        None,
        0.03,
        [39999.99999999074, 89999.9999999924, -10000.000000010526],
    ),
    (
        "one_segment",
        6,
        [-0.0002212173364241309, -0.010018805596712196, 0.0983967987978269],
        None,
        0.03,
        [39999.999999991276, 89999.9999999924, -10000.000000010526],
    ),
    (
        "one_segment",
        24,
        [-0.0002212174861837086, -0.010018987231257133, 0.09839677663920851],
        None,
        0.03,
        [39999.99999999154, 89999.99999999268, -10000.000000010403],
    ),
    (
        "two_segment",
        4,
        [0.002454930808845047, -0.03440778887118222, 0.2076682043334368],
        [0.022688419736993457, -0.14819701382311373, 0.9886975678658028],
        0.02,
        [
            25020.907306971807,
            74533.61437214095,
            -14594.285627590594,
            24917.657090357356,
            4817.66629742499,
            55123.167601216235,
        ],
    ),
    (
        "two_segment",
        6,
        [0.002466167398678283, -0.03459297613693071, 0.20763657173711458],
        [0.022713406773464777, -0.14856865103461292, 0.9886412175721301],
        0.02,
        [
            25022.407214898303,
            74535.65186048177,
            -14593.134939278474,
            24916.129080696475,
            4815.75985356286,
            55121.90987022028,
        ],
    ),
    (
        "two_segment",
        24,
        [0.0024662631312466145, -0.034594287544505296, 0.20763633354218916],
        [0.02271363097855277, -0.14857179174764154, 0.9886407404434995],
        0.02,
        [
            25022.432149937675,
            74535.68593431165,
            -14593.116268587451,
            24916.1064502299,
            4815.731073042039,
            55121.891889909675,
        ],
    ),
]

_MODELS = {}


def _model(name, n):
    if (name, n) not in _MODELS:
        _MODELS[name, n] = RobotModel(load_robot(name), n)
    return _MODELS[name, n]


@pytest.mark.parametrize("name,n,p_kpa,payload,expected", FORWARD)
def test_forward_tip_positions_are_unchanged(name, n, p_kpa, payload, expected):
    fw = solve_forward(_model(name, n), np.asarray(p_kpa, float) * 1e3, payload)
    assert fw.converged and fw.stable
    np.testing.assert_allclose(fw.position, expected, rtol=0, atol=1e-9)


@pytest.mark.parametrize("name,n,position,z_axis,payload,expected", INVERSE)
def test_inverse_pressures_are_unchanged(name, n, position, z_axis, payload, expected):
    inv = solve_inverse(_model(name, n), position, z_axis, payload_kg=payload)
    assert inv.success and inv.reachable, inv.message
    np.testing.assert_allclose(inv.pressures_pa, expected, rtol=0, atol=1e-2)  # Pa
    np.testing.assert_allclose(inv.forward.position, position, rtol=0, atol=1e-9)
