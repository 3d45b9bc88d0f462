"""Pictures of nets: what the artists show (spring colours and their scale,
supports and loads in the legend, residual-force arrows at the stated scale
and none when converged, the 3D view), not how the pixels look."""

import io
import math

import matplotlib
import numpy as np
import pytest
from ase import Atoms
from matplotlib.collections import LineCollection
from matplotlib.quiver import Quiver

from ase_maud import Maud, MaudCalculator
from ase_maud.form.pictures import (
    ARROW,
    COLOURS,
    MAX_ARROWS,
    SMALL_NET,
    VIEWS,
    arrow_scale,
    draw,
    figure,
    save_animation,
    save_picture,
    spring_values,
)
from ase_maud.scenes.catalogue import build

matplotlib.use('Agg')

SEEDS = [0, 1, 2]


def shaken(scene, seed, size=4, amount=0.3, Q=1.0):
    """A seeded scene with its points moved at random (not converged)."""
    atoms = build(scene, size, seed=seed, Q=Q)
    rng = np.random.default_rng(seed)
    dim = atoms.calc.dim
    atoms.positions[:, :dim] += rng.uniform(-amount, amount, (len(atoms), dim))
    atoms.calc.reset()
    return atoms


def relaxed(scene, seed, size=4):
    atoms = build(scene, size, seed=seed)
    with Maud(atoms, logfile=None) as opt:
        assert opt.run(fmax=1e-9, steps=500)
    return atoms


def legend_texts(ax):
    legend = ax.get_legend() or next(iter(ax.figure.legends), None)
    return [] if legend is None else [t.get_text() for t in legend.get_texts()]


def arrows(ax):
    """The residual-force arrows drawn on ``ax`` (a 2D Quiver or the 3D
    quiver's line collection), found by their label."""
    return [c for c in ax.collections if c.get_label().startswith('residual force')]


@pytest.mark.parametrize('seed', SEEDS)
@pytest.mark.parametrize('scene', ['net2d', 'hanging_net'])
def test_springs_are_coloured_by_force_with_a_colour_bar(tmp_path, scene, seed):
    Q = 1.5 + seed
    atoms = shaken(scene, seed, Q=Q)
    fig = save_picture(atoms, tmp_path / 'net.png')
    ax, bar = fig.axes
    lines = next(c for c in ax.collections if isinstance(c, LineCollection)
                 and c.get_array() is not None)
    i, j = atoms.calc.springs.T
    forces = Q * np.linalg.norm(atoms.positions[i] - atoms.positions[j], axis=1)
    assert np.allclose(lines.get_array(), forces, rtol=1e-12)
    assert (bar.get_ylabel() or bar.get_xlabel()) == COLOURS['force']
    limits = bar.get_ylim() if bar.get_ylabel() else bar.get_xlim()   # 3D: horizontal
    assert limits == pytest.approx((forces.min(), forces.max()))
    expected = lines.cmap(lines.norm(forces))
    assert np.allclose(lines.get_colors(), expected)   # as drawn (savefig ran)
    assert (tmp_path / 'net.png').read_bytes()[:4] == b'\x89PNG'


@pytest.mark.parametrize('seed', SEEDS)
def test_spring_force_is_Q_q_L_and_length_is_L(seed):
    rng = np.random.default_rng(seed)
    positions = rng.normal(size=(7, 3))
    springs = np.array([(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (5, 6), (6, 0), (0, 3)])
    q = rng.uniform(0.1, 3.0, len(springs))
    Q = rng.uniform(0.5, 2.0)
    atoms = Atoms(positions=positions)
    atoms.calc = MaudCalculator(springs=springs, Q=Q, q=q)
    lengths = np.array([math.dist(positions[a], positions[b]) for a, b in springs])
    assert np.allclose(spring_values(atoms, 'length'), lengths, rtol=1e-12)
    assert np.allclose(spring_values(atoms, 'force'), Q * q * lengths, rtol=1e-12)
    atoms.calc.set(q=None)   # no force densities: q = 1
    assert np.allclose(spring_values(atoms, 'force'), Q * lengths, rtol=1e-12)
    assert spring_values(atoms, 'none') is None
    with pytest.raises(ValueError, match="colour must be one of force, length, none"):
        spring_values(atoms, 'tension')


@pytest.mark.parametrize('seed', SEEDS)
def test_colour_by_length_or_none(tmp_path, seed):
    atoms = shaken('hanging_net', seed)
    fig = save_picture(atoms, tmp_path / 'length.png', colour='length')
    assert (fig.axes[1].get_ylabel() or fig.axes[1].get_xlabel()) == COLOURS['length']
    fig = save_picture(atoms, tmp_path / 'plain.png', colour='none')
    assert len(fig.axes) == 1   # no colour bar
    lines = [c for c in fig.axes[0].collections if isinstance(c, LineCollection)
             and not c.get_label().startswith('residual')]
    assert lines[0].get_array() is None
    assert np.allclose(lines[0].get_colors(), matplotlib.colors.to_rgba('0.55'))


@pytest.mark.parametrize('seed', SEEDS)
@pytest.mark.parametrize('scene', ['net2d', 'hanging_net'])
def test_no_arrows_when_converged(scene, seed):
    atoms = relaxed(scene, seed)
    fig, ax = figure(atoms.calc.dim)
    draw(ax, atoms)
    assert arrows(ax) == []
    assert not any(text.startswith('residual force') for text in legend_texts(ax))
    assert 'support (fixed)' in legend_texts(ax)
    # the same net judged at a tolerance below its forces: arrows
    fmax = np.linalg.norm(atoms.get_forces(), axis=1).max()
    fig, ax = figure(atoms.calc.dim)
    draw(ax, atoms, ftol=fmax / 2)
    assert len(arrows(ax)) == 1


@pytest.mark.parametrize('seed', SEEDS)
def test_arrows_are_forces_at_the_stated_scale(seed):
    atoms = shaken('net2d', seed)
    fig, ax = figure(2)
    draw(ax, atoms)
    (quiver,) = arrows(ax)
    assert isinstance(quiver, Quiver)
    text = next(t for t in legend_texts(ax) if t.startswith('residual force'))
    scale = float(text.split('= ')[1].split(' force')[0])
    free = np.ones(len(atoms), bool)
    free[atoms.constraints[0].index] = False
    forces = atoms.get_forces()[free, :2]
    assert np.allclose(np.column_stack([quiver.U, quiver.V]) * scale, forces, rtol=1e-3)
    assert quiver.scale == 1 and quiver.scale_units == 'xy'   # one data unit per unit


@pytest.mark.parametrize('seed', SEEDS)
def test_arrow_scale_is_the_least_1_2_5_number(seed):
    rng = np.random.default_rng(seed)
    for largest, extent in 10.0 ** rng.uniform(-8, 8, (50, 2)):
        scale = arrow_scale(largest, extent)
        mantissa = scale / 10.0 ** math.floor(math.log10(scale) + 1e-9)
        assert min(abs(mantissa - m) for m in (1, 2, 5)) < 1e-9
        assert largest / scale <= ARROW * extent * (1 + 1e-9)   # short enough
        assert largest / scale > ARROW * extent / 2.5 * (1 - 1e-9)   # and no shorter


@pytest.mark.parametrize('seed', SEEDS)
def test_supports_and_loads_in_the_legend(seed):
    """Supports as markers, loads as arrows at their stated scale (of the
    free points only)."""
    atoms = shaken('net2d', seed)
    loads = np.zeros((len(atoms), 3))
    rng = np.random.default_rng(seed)
    loaded = rng.choice(len(atoms), 5, replace=False)
    loads[loaded, :2] = rng.normal(size=(5, 2))
    atoms.calc.set(loads=loads)
    fig, ax = figure(2)
    draw(ax, atoms)
    texts = legend_texts(ax)
    assert {'free point', 'support (fixed)'} <= set(texts)
    fixed = set(atoms.constraints[0].index.tolist())
    (quiver,) = [c for c in ax.collections if c.get_label().startswith('load: ')]
    free = sorted(set(loaded.tolist()) - fixed)
    scale = float(quiver.get_label().split('= ')[1].split(' force')[0])
    assert np.allclose(np.column_stack([quiver.U, quiver.V]) * scale, loads[free, :2],
                       rtol=1e-3)


def test_large_nets_mark_supports_only_and_thin_their_arrows():
    """Above SMALL_NET points no free-point markers; about MAX_ARROWS load
    arrows, spread over the net, the legend saying how."""
    atoms = build('hanging_net', 30, seed=0)   # 900 points
    assert len(atoms) > SMALL_NET
    free = ~np.isin(np.arange(len(atoms)), atoms.constraints[0].index)
    atoms.calc.set(loads=np.where(free[:, None], [0.0, 0.0, -0.1], 0.0))
    fig, ax = figure(3)
    draw(ax, atoms)
    texts = legend_texts(ax)
    assert 'free point' not in texts and 'support (fixed)' in texts
    (load,) = [text for text in texts if text.startswith('load: arrow 1 length unit = ')]
    assert 'square)' in load
    (quiver,) = [c for c in ax.collections if c.get_label() == load]
    fig.savefig(io.BytesIO(), format='png')   # a 3D collection projects when drawn
    drawn = len(quiver.get_segments()) / 3   # a shaft and two head strokes each
    assert MAX_ARROWS / 3 < drawn <= 1.5 * MAX_ARROWS


@pytest.mark.parametrize('view', ['iso'])
def test_orthographic_view_from_a_side(view):
    """(top, front and side are drawn flat: tests/form/test_pictures_readable.py)"""
    atoms = shaken('hanging_net', 0)
    fig, ax = figure(3, view)
    draw(ax, atoms)
    assert (ax.elev, ax.azim) == VIEWS[view]
    assert ax._focal_length == np.inf   # matplotlib's orthographic projection
    edge_on = {'top': 'z', 'front': 'y', 'side': 'x'}.get(view)
    for axis in 'xyz':
        ticks = getattr(ax, f'get_{axis}ticks')()
        assert (len(ticks) == 0) == (axis == edge_on)
    with pytest.raises(ValueError, match='view must be one of top, front, side, iso'):
        figure(3, 'below')


def test_animation_writes_every_frame(tmp_path):
    frames = [shaken('net2d', seed, amount=amount) for seed, amount in ((0, 0.3), (0, 0.1))]
    assert save_animation(frames, tmp_path / 'run.gif') == 2
    assert (tmp_path / 'run.gif').read_bytes()[:6] == b'GIF89a'


@pytest.mark.parametrize('colour', ['force', 'length'])
def test_labels_give_each_member_its_value(tmp_path, colour):
    atoms = shaken('hanging_net', int(np.random.default_rng().integers(100)))
    fig = save_picture(atoms, tmp_path / 'labels.png', colour=colour, labels=True)
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert texts == [f'{v:.3g}' for v in spring_values(atoms, colour)]
    with pytest.raises(ValueError, match="colour 'none' has none"):
        save_picture(atoms, tmp_path / 'plain.png', colour='none', labels=True)
    big = build('hanging_net', 20, seed=0)
    with pytest.raises(ValueError, match=r'springs are too many to label \(at most 300\)'):
        save_picture(big, tmp_path / 'big.png', labels=True)
