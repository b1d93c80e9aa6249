"""The printed numbers and counts of bellow_ancf_ros/cli/output.py (tables, demos, benches)."""

import math

import numpy as np
import pytest

from bellow_ancf_ros.cli.output import count, number, numbers


@pytest.mark.parametrize('value, spec, text', [
    (-1e-5, '.3f', '0.000'),
    (-1e-5, '+.3f', '+0.000'),
    (-1e-5, '+8.3f', '  +0.000'),
    (-0.0, '9.3f', '    0.000'),
    (-0.04, '.1f', '0.0'),
    (-0.0, 'g', '0'),
    (-1e-9, '.2e', '-1.00e-09'),      # not zero at this spec: the sign stays
    (-0.0005, '.3f', '-0.001'),       # rounds away from zero: the sign stays
    (-0.25, '+.2f', '-0.25'),
    (0.0, '+.3f', '+0.000'),
    (np.float64(-1e-7), '7.2f', '   0.00'),
    (-1e-6, '.1%', '0.0%'),
])
def test_number_never_prints_a_negative_zero(value, spec, text):
    assert number(value, spec) == text


def test_number_keeps_non_finite_values():
    assert number(-math.inf, '.3f') == '-inf'
    assert number(math.nan, '.3f') == 'nan'


def test_numbers_is_a_bracketed_list_without_negative_zeros():
    assert numbers([0.1, -1e-4, -0.2944]) == '[0.100, 0.000, -0.294]'
    assert numbers(np.array([42.004, -0.001]), '.2f') == '[42.00, 0.00]'
    assert numbers([]) == '[]'


@pytest.mark.parametrize('n, text', [(0, '0 dropouts'), (1, '1 dropout'), (2, '2 dropouts')])
def test_count_is_singular_for_one(n, text):
    assert count(n, 'dropout') == text


def test_count_takes_an_irregular_plural():
    assert count(1, 'case', 'cases') == '1 case'
    assert count(3, 'mode shape', 'mode shapes') == '3 mode shapes'
    assert count(2, 'axis', 'axes') == '2 axes'
