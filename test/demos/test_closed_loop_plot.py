"""The main job's pictures (demos/closed_loop_plot.py), drawn from a synthetic results file."""

import itertools
import json

import matplotlib
from matplotlib.backends.backend_agg import FigureCanvasAgg
import numpy as np
import pytest

from bellow_ancf_ros.demos import closed_loop_plot as pictures
from demo_results import results

matplotlib.use('Agg')

RED = matplotlib.colors.to_rgba(pictures.MISSED)


def _titles(fig):
    """Every title of the figure (axes, subfigures, figure) and axes' x labels (non-empty)."""
    texts = []
    for ax in fig.get_axes():
        texts += [ax.title, ax._left_title, ax._right_title, ax.xaxis.label]
    for sub in [fig, *fig.subfigs]:
        if getattr(sub, '_suptitle', None) is not None:
            texts.append(sub._suptitle)
    return [t for t in texts if t.get_text()]


def overlapping_titles(fig):
    """Pairs of titles whose drawn extents overlap, and titles outside the figure."""
    FigureCanvasAgg(fig)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    boxes = [(t.get_text(), t.get_window_extent(renderer)) for t in _titles(fig)]
    bad = [(a, b) for (a, ea), (b, eb) in itertools.combinations(boxes, 2) if ea.overlaps(eb)]
    whole = fig.bbox
    bad += [(a, 'outside the figure') for a, e in boxes
            if e.x0 < whole.x0 - 1 or e.x1 > whole.x1 + 1 or e.y1 > whole.y1 + 1]
    return bad


def test_the_overlap_check_finds_overlapping_titles():
    from matplotlib.figure import Figure
    fig = Figure(figsize=(6, 3))
    for ax in fig.subplots(1, 4):
        ax.set_title('a long title that does not fit over its narrow axes')
    assert overlapping_titles(fig)


@pytest.mark.parametrize('page', ['summary', 1, 2])
def test_no_title_overlaps_another(page):
    data = results(cl_10x_mm=2.0, held_50g_mm=0.9)   # three goals missed at 10x: long labels
    fig = (pictures.summary_figure(data) if page == 'summary'
           else pictures.detail_figure(data, page))
    assert len(_titles(fig)) > 5
    assert overlapping_titles(fig) == []


def test_a_missed_goal_is_a_red_bar_and_a_line_that_names_it():
    data = results(cl_10x_mm=0.7)   # one segment at 10x misses its 0.5 mm RMSE goal
    fig = pictures.summary_figure(data)
    red = [ax for ax in fig.get_axes()
           if any(np.allclose(p.get_facecolor(), RED) for p in ax.patches)]
    labels = sorted(ax.get_xlabel() for ax in red)
    assert labels == ['MISSED: RMSE 0.700 > 0.500 mm', 'MISSED: held 0.610 > 0.500 mm']
    several = pictures.summary_figure(results(cl_10x_mm=2.0))   # two segments miss mm and deg
    assert 'MISSED: RMSE 2.000 > 1.000 mm\nRMSE 0.800 > 0.500 deg' in [
        ax.get_xlabel() for ax in several.get_axes()]
    met = [ax for ax in fig.get_axes() if ax.get_xlabel() == 'closed loop: every goal met']
    assert len(met) == 6 and not any(np.allclose(p.get_facecolor(), RED)
                                     for ax in met for p in ax.patches)
    step = next(ax for ax in fig.get_axes() if ax.get_title().startswith('10 mm step'))
    assert step.get_xlabel() == 'goals met'
    missed = pictures.summary_figure(results(zvd_mm=0.2))
    step = next(ax for ax in missed.get_axes() if ax.get_title().startswith('10 mm step'))
    assert step.get_xlabel() == 'MISSED: shaped swing 0.200 > 0.100 mm'


def test_the_closed_loop_path_is_drawn_above_the_target_and_only_the_evaluated_samples():
    data = results()
    fig = pictures.detail_figure(data, 2)
    paths = [ax for ax in fig.get_axes() if ax.get_title() == 'path seen from above']
    assert len(paths) == 5   # 1x, 4x, 10x, and with 50 g 1x and 10x
    for ax in paths:
        lines = {ln.get_label(): ln for ln in ax.get_lines()}
        assert lines['closed loop'].get_zorder() > lines['target'].get_zorder()
        assert all(lines[m].get_zorder() < lines['closed loop'].get_zorder()
                   for m in ('feedforward', 'dynamic FF') if m in lines)
        for line in lines.values():
            assert len(line.get_xdata()) == pictures_samples(data)
        assert ax.xaxis.get_major_formatter().get_offset() == ''


def pictures_samples(data):
    """Samples per run in the results file (the same for every run of the synthetic file)."""
    return len(data['cases'][0]['runs']['none']['series']['t_s'])


def test_redrawn_from_the_file_without_a_run(tmp_path, capsys):
    path = tmp_path / 'demo_results.json'
    path.write_text(json.dumps(results()))
    out = tmp_path / 'pics' / 'demo_tracking.png'
    assert pictures.main([str(path), '--plot', str(out)]) == 0
    files = [out, tmp_path / 'pics' / 'demo_tracking_1seg.png',
             tmp_path / 'pics' / 'demo_tracking_2seg.png']
    for f in files:
        assert f.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    assert sorted(tmp_path.glob('pics/*')) == sorted(files)
    assert capsys.readouterr().out.count(' written') == 3


def test_a_file_that_is_not_a_results_file_is_refused(tmp_path, capsys):
    path = tmp_path / 'x.json'
    path.write_text('{"cases": [{"key": 1}]}')
    assert pictures.main([str(path), '--plot', str(tmp_path / 'p.png')]) == 2
    assert 'not a make demo results file' in capsys.readouterr().err
    assert pictures.main([str(tmp_path / 'missing.json')]) == 2
    assert 'cannot read a results file' in capsys.readouterr().err
