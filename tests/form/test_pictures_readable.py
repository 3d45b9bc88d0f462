"""Pictures a reader can read: no label under the colour bar or another
label, the legend inside every GIF frame, flat views drawn flat, minus
signs shown, '1 minimum'. Checked on the drawn extents, not on pixels."""

import numpy as np
import pytest

pytest.importorskip('matplotlib')
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from PIL import Image  # noqa: E402

from ase_maud.form.force_density import solve_force_density  # noqa: E402
from ase_maud.form.pictures import (  # noqa: E402
    FLAT_VIEWS,
    _colour_bar,
    draw,
    figure,
    save_animation,
    save_disconnectivity,
)
from ase_maud.scenes.catalogue import build  # noqa: E402


def hung(size, seed, depth=1.0):
    """A hanging net at its a = 0 form, shaken a little (residual arrows)."""
    atoms = build('hanging_net', size, seed=seed)
    atoms.calc.set(a=0.0)
    solve_force_density(atoms)
    rng = np.random.default_rng(seed)
    atoms.positions[:, 2] *= depth
    free = ~np.isin(np.arange(len(atoms)), atoms.constraints[0].index)
    atoms.positions[free] += rng.normal(0, 0.01, (free.sum(), 3))
    return atoms


def extents(fig, artists):
    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    return [a.get_window_extent(renderer) for a in artists
            if a.get_visible() and a.get_text()]


def overlap(a, b):
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


@pytest.mark.parametrize('view', ['iso', 'top', 'front', 'side'])
@pytest.mark.parametrize('seed, size, depth', [(0, 8, 1.0), (1, 12, 0.05), (2, 6, 20.0)])
def test_no_axis_label_or_tick_label_lies_under_the_colour_bar(view, seed, size, depth):
    atoms = hung(size, seed, depth)
    fig, ax = figure(3, view)
    _colour_bar(fig, ax, draw(ax, atoms), 'force')
    bar = fig.axes[1]
    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    box = bar.get_window_extent(renderer)
    axes = 'xyz' if ax.name == '3d' else 'xy'
    texts = [getattr(ax, f'{a}axis').label for a in axes]
    texts += [t for a in axes for t in getattr(ax, f'get_{a}ticklabels')()]
    for extent in extents(fig, texts):
        assert not overlap(extent, box)


@pytest.mark.parametrize('view', list(FLAT_VIEWS))
def test_views_along_an_axis_are_drawn_flat_on_the_two_axes_seen(view):
    atoms = hung(8, 3)
    fig, ax = figure(3, view)
    draw(ax, atoms)
    assert ax.name != '3d'
    right, up = ('xyz'[k] for k in FLAT_VIEWS[view])
    assert (ax.get_xlabel(), ax.get_ylabel()) == (right, up)
    segments = ax.collections[0].get_segments()
    springs = atoms.calc.springs
    np.testing.assert_allclose(np.asarray(segments),
                               atoms.positions[springs][:, :, list(FLAT_VIEWS[view])])


def test_minus_signs_show_and_tick_labels_do_not_overlap():
    atoms = hung(10, 4)   # hangs below z = 0
    fig, ax = figure(3, 'front')
    draw(ax, atoms)
    labels = [t for t in ax.get_yticklabels()
              if ax.get_ylim()[0] <= t.get_position()[1] <= ax.get_ylim()[1]]
    boxes = extents(fig, labels)
    assert any(t.get_text().startswith('\N{MINUS SIGN}') for t in labels)
    for i, a in enumerate(boxes):
        assert not any(overlap(a, b) for b in boxes[i + 1:])


@pytest.mark.parametrize('view', ['iso', 'front'])
def test_the_legend_is_inside_every_gif_frame(tmp_path, view):
    frames = [hung(8, seed) for seed in (5, 6)]
    captured = []
    import ase_maud.form.pictures as pictures

    original = pictures.draw

    def spy(ax, *args, **kwargs):
        lines = original(ax, *args, **kwargs)
        fig = ax.figure
        renderer = FigureCanvasAgg(fig).get_renderer()
        legend = ax.get_legend() or fig.legends[0]
        captured.append((legend.get_window_extent(renderer), fig.bbox))
        return lines

    pictures.draw = spy
    try:
        save_animation(frames, tmp_path / 'run.gif', view=view)
    finally:
        pictures.draw = original
    assert len(captured) >= 2
    for box, frame in captured:
        assert frame.x0 <= box.x0 and box.x1 <= frame.x1
        assert frame.y0 <= box.y0 and box.y1 <= frame.y1
    assert Image.open(tmp_path / 'run.gif').n_frames == 2


@pytest.mark.parametrize('count, title', [(1, '1 minimum, 0 saddles'),
                                          (2, '2 minima, 1 saddle')])
def test_disconnectivity_graph_says_one_minimum_and_keeps_its_y_label(tmp_path, count, title):
    energies = [0.0, 0.5][:count]
    saddles, joins = ([1.0], [(0, 1)]) if count == 2 else ([], [])
    path = tmp_path / 'graph.png'
    import matplotlib.figure

    made = []
    original = matplotlib.figure.Figure.savefig

    def keep(self, *args, **kwargs):
        made.append((self, kwargs))
        return original(self, *args, **kwargs)

    matplotlib.figure.Figure.savefig = keep
    try:
        save_disconnectivity(energies, saddles, joins, path)
    finally:
        matplotlib.figure.Figure.savefig = original
    fig, kwargs = made[0]
    assert fig.axes[0].get_title() == title
    assert kwargs.get('bbox_inches') == 'tight'   # the y label is not clipped
    assert Image.open(path).size[0] > 0
