"""What the PNG plots of ``bellow-ancf`` show: no hidden points, readable axes, distinct colours.

Each command runs in-process with small inputs; its figure is taken at
``save_figure`` (written to the PNG as well) and checked in display
coordinates after the figure has been drawn:

* no legend covers a data point of any 2-D axes, and every legend is inside
  the figure (``convergence``, ``compare-pcc``, ``track``, ``workspace``,
  the calibration residuals);
* the 3-D z axis of ``track`` has no offset label, spans at least 10 mm,
  and its label is inside the figure, clear of the next panel;
* ``workspace`` draws each actuation scheme in its own colour;
* the calibration residuals are on log axes that reach the calibrated
  errors.
"""

from types import SimpleNamespace

import numpy as np
import pytest

from bellow_ancf_ros import cli
from bellow_ancf_ros.cli import calibrate as cli_calibrate
from bellow_ancf_ros.cli import output, studies, track


@pytest.fixture
def figures(monkeypatch):
    """The figures the commands save (drawn), in order."""
    saved = []

    def keep(fig, path):
        output.save_figure(fig, path)
        saved.append(fig)

    for module in (studies, track, cli_calibrate):
        monkeypatch.setattr(module, 'save_figure', keep)
    return saved


def run(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    capsys.readouterr()
    return code


def _legends(fig):
    return list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend()]


def covered_points(fig):
    """``(legend label, axes title, x, y)`` of every 2-D data point under a legend."""
    renderer = fig.canvas.get_renderer()
    boxes = [(lg, lg.get_window_extent(renderer)) for lg in _legends(fig)]
    hits = []
    for ax in fig.axes:
        if ax.name == '3d':
            continue
        for line in ax.lines:
            xy = line.get_xydata()
            xy = xy[np.all(np.isfinite(xy), axis=1)]
            if not len(xy):
                continue
            for px, py in ax.transData.transform(xy):
                for lg, box in boxes:
                    if box.x0 + 1 < px < box.x1 - 1 and box.y0 + 1 < py < box.y1 - 1:
                        hits.append((lg.get_texts()[0].get_text(), ax.get_title(), px, py))
    return hits


def assert_legends_clear(fig):
    assert _legends(fig), 'no legend'
    assert not covered_points(fig), covered_points(fig)[:5]
    page = fig.bbox
    renderer = fig.canvas.get_renderer()
    for lg in _legends(fig):
        box = lg.get_window_extent(renderer)
        assert page.x0 - 1 <= box.x0 and box.x1 <= page.x1 + 1, box
        assert page.y0 - 1 <= box.y0 and box.y1 <= page.y1 + 1, box


def test_the_legend_check_finds_a_legend_over_points():
    """The check itself: a legend placed over the points is reported."""
    fig = output.figure(4, 3)
    ax = fig.add_subplot(1, 1, 1)
    xs = np.linspace(0, 1, 50)
    ax.plot(xs, np.full_like(xs, 0.5), 'o', label='a line of points across the middle')
    ax.legend(loc='center')
    output.save_figure(fig, '/dev/null')
    assert covered_points(fig)


def test_convergence_legend_hides_no_point(capsys, tmp_path, figures):
    code = run(capsys, 'convergence', '--max-elements', 4, '--reference', 8, '--repeats', 1,
               '--quiet', '--plot', tmp_path / 'c.png')
    assert code == 0 and len(figures) == 1
    assert_legends_clear(figures[0])


def test_compare_pcc_legends_hide_no_point(capsys, tmp_path, figures):
    code = run(capsys, 'compare-pcc', '--points', 3, '--payload-kg', 0, 0.05, '--quiet',
               '--plot', tmp_path / 'p.png')
    assert code == 0 and len(figures) == 1
    assert_legends_clear(figures[0])


def test_track_two_segments_z_axis_without_offset_and_its_label_fits(capsys, tmp_path,
                                                                     figures):
    code = run(capsys, 'track', '--config', 'two_segment', '--trajectory', 'bending_circle',
               '--bending-angle-deg', 10, '--points', 8, '--quiet', '--plot', tmp_path / 't.png')
    assert code == 0 and len(figures) == 1
    fig = figures[0]
    ax3 = [ax for ax in fig.axes if ax.name == '3d'][0]
    # the circle is at one height: z varies by round-off only
    assert ax3.zaxis.get_offset_text().get_text() == ''
    z0, z1 = ax3.get_zlim()
    assert z1 - z0 >= 10.0
    assert [t.get_text() for t in ax3.zaxis.get_ticklabels() if t.get_text()]
    renderer = fig.canvas.get_renderer()
    label = ax3.zaxis.label.get_window_extent(renderer)
    assert ax3.zaxis.label.get_text() == 'z [mm]'
    assert fig.bbox.x0 <= label.x0 and label.x1 <= fig.bbox.x1
    assert fig.bbox.y0 <= label.y0 and label.y1 <= fig.bbox.y1
    neighbour = [ax for ax in fig.axes if ax.get_title() == 'top view'][0]
    assert not label.overlaps(neighbour.yaxis.label.get_window_extent(renderer))
    assert not label.overlaps(neighbour.get_window_extent(renderer))
    assert_legends_clear(fig)


def test_track_z_limits_keep_a_real_climb(capsys, tmp_path, figures):
    """A trajectory that does climb keeps its own range (the minimum span only widens)."""
    code = run(capsys, 'track', '--trajectory', 'space_spiral', '--points', 12, '--quiet',
               '--plot', tmp_path / 't.png')
    assert code == 0
    ax3 = [ax for ax in figures[0].axes if ax.name == '3d'][0]
    z = np.concatenate([np.asarray(line.get_data_3d()[2]) for line in ax3.lines])
    z0, z1 = ax3.get_zlim()
    assert z0 <= z.min() and z.max() <= z1 and z1 - z0 < 3 * max(z.max() - z.min(), 10.0)


def test_workspace_two_segments_one_colour_per_scheme(capsys, tmp_path, figures):
    code = run(capsys, 'workspace', '--config', 'two_segment', '--points', 3, '--quiet',
               '--plot', tmp_path / 'w.png')
    assert code == 0 and len(figures) == 1
    fig = figures[0]
    top = [ax for ax in fig.axes if ax.get_title() == 'top view'][0]
    colours = {tuple(np.round(np.array(matplotlib_rgba(line.get_color())), 6))
               for line in top.lines}
    assert len(top.lines) == 4 and len(colours) == 4      # the four schemes of the paper
    legend_labels = [t.get_text() for lg in fig.legends for t in lg.get_texts()]
    assert sum(label.startswith(('1:', '2:', '3:', '4:')) for label in legend_labels) == 4
    assert_legends_clear(fig)


def test_workspace_payloads_by_line_style(capsys, tmp_path, figures):
    code = run(capsys, 'workspace', '--points', 3, '--payload-kg', 0, 0.05, '--quiet',
               '--plot', tmp_path / 'w.png')
    assert code == 0
    top = [ax for ax in figures[0].axes if ax.get_title() == 'top view'][0]
    colours = {tuple(np.round(matplotlib_rgba(line.get_color()), 6)) for line in top.lines}
    styles = {line.get_linestyle() for line in top.lines}
    assert len(colours) == 18 and len(styles) == 2          # 18 schemes, 2 payloads


def matplotlib_rgba(colour):
    from matplotlib.colors import to_rgba
    return np.array(to_rgba(colour))


def test_calibration_residuals_on_log_axes_that_reach_the_calibrated_errors(tmp_path,
                                                                            figures):
    rng = np.random.default_rng(0)
    n = 40
    result = SimpleNamespace(
        samples=n, errors_before_mm=rng.uniform(0.2, 5.5, n),
        errors_after_mm=rng.uniform(0.01, 0.08, n),
        angle_errors_before_deg=rng.uniform(0.2, 6.0, n),
        angle_errors_after_deg=np.r_[0.0, rng.uniform(0.002, 0.07, n - 1)],  # an exact zero
        rmse_before_mm=3.8, rmse_after_mm=0.058, rmse_before_deg=4.3, rmse_after_deg=0.039)
    cli_calibrate.plot_residuals(result, str(tmp_path / 'r.png'))
    fig = figures[0]
    axes = [ax for ax in fig.axes if ax.lines]
    assert len(axes) == 2
    for ax, after in zip(axes, (result.errors_after_mm, result.angle_errors_after_deg)):
        assert ax.get_yscale() == 'log'
        lo, hi = ax.get_ylim()
        positive = after[after > 0]
        assert lo <= positive.min() and hi >= 5.0
        # the calibrated points span a decade or more of the axis, not a flat line at 0
        assert np.log10(hi / lo) < 4 * np.log10(5.5 / positive.min())
    assert_legends_clear(fig)
