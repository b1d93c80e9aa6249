"""core.status: the two status vocabularies, their one message table, and what "usable" means."""

import json

import pytest

from bellow_ancf_ros.core import (ForwardStatus, InverseStatus, RobotModel, load_robot,
                                  solve_forward, solve_inverse)
from bellow_ancf_ros.core.status import MESSAGES, usable


def test_codes_are_the_documented_numbers():
    assert [int(s) for s in ForwardStatus] == [0, 1, 2, 3, 4, 5, 6, 7, 8]
    assert {s.name: int(s) for s in InverseStatus} == {
        'REACHED': 0, 'UNREACHABLE': 1, 'FAILED': 2, 'UNSTABLE': 6, 'TIME_BUDGET': 7,
        'ITERATION_BUDGET': 8}
    # codes 6 to 8 mean the same in both problems
    for code in (6, 7, 8):
        assert ForwardStatus(code) == InverseStatus(code)
        assert ForwardStatus(code).message == InverseStatus(code).message


def test_every_code_has_a_message_and_json_carries_the_number():
    for enum in (ForwardStatus, InverseStatus):
        assert set(MESSAGES[enum]) == set(enum)
        assert all(m and m == m.strip() for m in MESSAGES[enum].values())
    assert json.dumps({'status': ForwardStatus.TIME_BUDGET}) == '{"status": 7}'
    assert ForwardStatus.CONVERGED.message == 'converged'
    assert InverseStatus.REACHED.message == 'target reached'


@pytest.mark.parametrize('converged,stable,ok', [
    (True, True, True), (True, None, True), (True, False, False),
    (False, None, False), (False, True, False)])
def test_usable(converged, stable, ok):
    assert usable(converged, stable) is ok


def test_results_carry_enum_statuses_and_plain_json():
    model = RobotModel(load_robot('one_segment'))
    fw = solve_forward(model, [50e3, 0.0, 0.0])
    assert fw.status is ForwardStatus.CONVERGED and fw.success and fw.stable
    d = fw.to_dict()
    assert d['status'] == 0 and type(d['status']) is int
    skipped = solve_forward(model, [50e3, 0.0, 0.0], check_stability=False)
    assert skipped.stable is None and skipped.success  # as its docstring says
    inv = solve_inverse(model, fw.position, warm_start=fw)
    assert inv.status is InverseStatus.REACHED and inv.success
    assert type(inv.to_dict()['status']) is int and json.loads(json.dumps(inv.to_dict()))
    far = solve_inverse(model, fw.position + [0.0, 0.0, 1.0])
    assert far.status == InverseStatus.UNREACHABLE and not far.success
    assert far.message.startswith(InverseStatus.UNREACHABLE.message)
    heavy = solve_forward(RobotModel(load_robot('two_segment')), [0.0] * 6, payload_kg=0.25)
    assert heavy.status is ForwardStatus.UNSTABLE and not heavy.success
    assert heavy.message.startswith(ForwardStatus.UNSTABLE.message)
