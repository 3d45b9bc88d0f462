"""Pictures of nets, as a form finder reads them: PNG (or any format
matplotlib writes) or an animated GIF.

A net is an :class:`ase.Atoms` with a :class:`~ase_maud.MaudCalculator`
(``calc.springs``, ``calc.dim``). What is drawn:

- springs, one line collection, coloured (:data:`COLOURS`) by their force
  ``Q q L`` (``q`` the spring's force density, a multiplier of ``Q``, 1
  where the calculator has none; the net's force units), by their length
  ``L``, or plain grey, with a colour bar; thinner on large nets;
- supports (points with every coordinate fixed) as black squares, and
  free points as small dots on nets of at most :data:`SMALL_NET` points
  (above, the springs alone show the net), named in a legend;
- the loads of the free points (a non-zero row of the calculator's
  ``loads``) as orange arrows, and the residual forces ``f`` of the free
  points as red arrows, each at a stated scale: an arrow one length unit
  long is :func:`arrow_scale` force units (a 1-2-5 number, so that the
  longest arrow is at most :data:`ARROW` of the picture), said in the
  legend; at most :data:`MAX_ARROWS` of each; no residual arrows when the
  net is converged (``max |f| <= ftol``, by default
  :func:`ase_maud.analysis.stationary.force_tolerance`).

``dim=2`` nets are drawn in their plane; others seen from a side of
:data:`VIEWS`: ``iso`` in an orthographic 3D view with equal scales on the
three axes, the box tight around the net (:data:`MARGIN`, :data:`THINNEST`);
``top``, ``front`` and ``side`` look straight along an axis, so they are
drawn flat, on the two axes seen (:data:`FLAT_VIEWS`): the 3D axes' labels
and ticks, seen edge-on, would overlap. Figures are
made without pyplot (:class:`matplotlib.figure.Figure`, rendered by Agg): no
display needed and no global backend changed.
"""

from __future__ import annotations

import io
import math
import os
from collections.abc import Sequence

import numpy as np
from ase import Atoms
from matplotlib.animation import FuncAnimation, PillowWriter
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator
from mpl_toolkits.mplot3d.art3d import Line3DCollection

from ase_maud.analysis.stationary import force_tolerance
from ase_maud.calculator.identify import potential_of
from ase_maud.physics.pair_law import spring_force
from ase_maud.physics.topology import fixed_atoms

#: Longest force arrow at most this fraction of the picture's largest extent.
ARROW = 0.15
#: What the springs' colour shows: colour bar label, or None (plain grey).
#: Force and length are in the net's own units (those of its coordinates and
#: of ``Q``), whatever ``a``.
COLOURS = {'force': 'member force Q q L (force units)',
           'length': 'spring length L (length units)', 'none': None}
#: Nets of up to this many points get a marker at every point; larger ones
#: at their supports only, smaller (the springs show the net).
SMALL_NET = 400
#: At most this many arrows of one kind (loads, residual forces) are drawn:
#: beyond it, those of points spread evenly, said in the legend.
MAX_ARROWS = 150
#: Longest load arrow at most this fraction of the picture's largest extent
#: (loads are context; residual forces get :data:`ARROW`).
LOAD_ARROW = 0.06
#: The most springs :func:`label_members` writes a value on.
MAX_LABELS = 300
#: Space around the net, a fraction of its largest extent on each side.
MARGIN = 0.03
#: A 3D box is at least this fraction of its largest extent along each axis
#: (a flat net keeps a visible thickness).
THINNEST = 0.05
#: 3D views, as matplotlib's (elevation, azimuth) in degrees: top looks down
#: z (x right, y up), front along +y (x right, z up), side along -x (y right,
#: z up), iso from (1, -1, 1)-ish.
VIEWS = {'top': (90.0, -90.0), 'front': (0.0, -90.0), 'side': (0.0, 0.0),
         'iso': (35.264, -45.0)}
#: The axis a view looks along, drawn without ticks.
EDGE_ON = {'top': 'z', 'front': 'y', 'side': 'x'}
#: The coordinates (columns) a view along an axis shows, right and up.
FLAT_VIEWS = {'top': (0, 1), 'front': (0, 2), 'side': (1, 2)}
#: Points between a 3D axis's tick labels and its label, and between its
#: tick marks and tick labels.
LABEL_PAD, TICK_PAD = 10.0, 4.0
#: A 3D box's zoom within its axes: below 1, so that tick labels and axis
#: labels stay inside the axes, clear of the colour bar beside them.
BOX_ZOOM = 0.75


def save_png(fig: Figure, path: str | os.PathLike, dpi: int = 72, colours: int = 64) -> None:
    """Save ``fig`` as a PNG of at most ``colours`` colours (Pillow's
    palette quantisation): line plots lose nothing visible and take a
    fraction of a full-colour file (the benchmark's figures kept in the
    docs)."""
    from PIL import Image  # matplotlib's own dependency

    buffer = io.BytesIO()
    fig.savefig(buffer, format='png', dpi=dpi)
    buffer.seek(0)
    image = Image.open(buffer).convert('RGB').quantize(colours)
    image.save(path, optimize=True)


def spring_q(calc) -> np.ndarray:
    """Each spring's force density ``q`` (a multiplier of ``Q``; its
    potential's, ones where it has none)."""
    q = calc.potential.q
    return np.ones(len(calc.springs)) if q is None else q


def spring_values(atoms: Atoms, colour: str) -> np.ndarray | None:
    """What the springs are coloured by (:data:`COLOURS`), one value per
    spring: the force ``Q q L`` (force units), the length ``L``, or None."""
    if colour not in COLOURS:
        raise ValueError(f'colour must be one of {", ".join(COLOURS)}, got {colour!r}')
    calc = atoms.calc
    d = atoms.positions[calc.springs[:, 0]] - atoms.positions[calc.springs[:, 1]]
    if colour == 'length':
        return np.linalg.norm(d, axis=1)
    if colour == 'force':
        Q = calc.potential.Q * spring_q(calc)
        return np.linalg.norm(spring_force(d, Q), axis=1)
    return None


def loaded_points(atoms: Atoms) -> np.ndarray:
    """Boolean mask of the points with a non-zero load (the potential's
    ``loads``, where it has loads; else none)."""
    potential = potential_of(atoms)
    if potential is None or potential.loads is None:
        return np.zeros(len(atoms), bool)
    return np.any(potential.loads != 0, axis=1)


def arrow_scale(largest_force: float, extent: float) -> float:
    """Force units per length unit of an arrow: the least 1, 2 or 5 times a
    power of ten at which an arrow of ``largest_force`` is at most
    :data:`ARROW` ``* extent`` long."""
    need = max(largest_force, 1e-300) / (ARROW * max(extent, 1e-300))
    power = 10.0 ** math.floor(math.log10(need))
    return next(m * power for m in (1, 2, 5, 10) if m * power >= need * (1 - 1e-12))


def _norm(values: Sequence[np.ndarray]) -> Normalize:
    """The colour scale from the least to the largest of ``values``."""
    every = np.concatenate(values)
    return Normalize(*((every.min(), every.max()) if every.size else (0.0, 1.0)))


def _limits(frames: Sequence[Atoms]) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper corners of a box tight around every frame's points,
    with a margin of :data:`MARGIN` of their largest extent on each side."""
    points = np.concatenate([atoms.positions for atoms in frames])
    low, high = points.min(axis=0), points.max(axis=0)
    margin = MARGIN * max((high - low).max(), 1e-12)
    return low - margin, high + margin


def figure(dim: int, view: str = 'iso') -> tuple[Figure, Axes]:
    """A figure with one 2D axes (``dim`` 2) or an orthographic 3D axes
    seen from ``view`` (:data:`VIEWS`), room left below for the legend."""
    if view not in VIEWS:
        raise ValueError(f'view must be one of {", ".join(VIEWS)}, got {view!r}')
    fig = Figure(figsize=(7.2, 5.6))
    solid = dim == 3 and view not in FLAT_VIEWS
    ax = fig.add_subplot(projection='3d' if solid else None)
    ax.net_columns = (0, 1, 2) if solid else FLAT_VIEWS.get(view, (0, 1)) if dim == 3 \
        else (0, 1)
    if solid:
        fig.subplots_adjust(left=0.02, right=0.98, bottom=0.16, top=0.94)
    elif dim == 3:   # the legend goes below the axes, inside the figure
        fig.subplots_adjust(bottom=0.26)
    orient(ax, view)
    return fig, ax


def orient(ax: Axes, view: str) -> None:
    """Axis labels; of a 3D axes also the orthographic projection from
    ``view``, the axis it looks along without ticks."""
    if ax.name != '3d':
        right, up = ('xyz'[k] for k in getattr(ax, 'net_columns', (0, 1)))
        ax.set(xlabel=right, ylabel=up)
        return
    ax.set_proj_type('ortho')
    ax.view_init(*VIEWS[view])
    for axis in 'xyz':
        if axis == EDGE_ON.get(view):
            getattr(ax, f'set_{axis}ticks')([])
        else:
            # labels clear of the tick labels, and tick labels clear of the tick marks
            # (which otherwise cross a tick label's minus sign in an edge-on view)
            edge_on = view in EDGE_ON   # an axis label seen flat needs more room
            getattr(ax, f'set_{axis}label')(axis, labelpad=LABEL_PAD * (2 if edge_on else 1))
            getattr(ax, f'{axis}axis').set_tick_params(pad=TICK_PAD)
            # a thin box (a flat net seen from the side) has room for few ticks
            getattr(ax, f'{axis}axis').set_major_locator(MaxNLocator(nbins=4))


def draw(ax: Axes, atoms: Atoms, colour: str = 'force',
         limits: tuple[np.ndarray, np.ndarray] | None = None,
         norm: Normalize | None = None, scale: float | None = None,
         ftol: float | None = None, title: str | None = None) -> LineCollection:
    """Draw the net ``atoms`` on ``ax`` (2D axes for dim 2, else 3D) as the
    module docstring says; return the springs (a LineCollection, coloured
    through ``norm`` unless ``colour`` is 'none').

    Axis labels and the 3D view are the axes' (:func:`figure`).
    ``limits`` (two corners), ``norm`` (of the spring values) and ``scale``
    (force units per length unit of an arrow) default to this frame's;
    ``ftol`` (force units) is the largest ``|f|`` of a converged net.
    """
    calc = atoms.calc
    columns = list(getattr(ax, 'net_columns', (0, 1, 2) if ax.name == '3d' else (0, 1)))
    dim = len(columns)
    x = atoms.positions[:, columns]
    forces = atoms.get_forces()[:, columns]
    size = np.linalg.norm(forces, axis=1)
    fixed = fixed_atoms(atoms)
    loaded = loaded_points(atoms) & ~fixed
    free = ~fixed
    small = len(atoms) <= SMALL_NET
    low, high = _limits([atoms]) if limits is None else limits
    extent = (high - low).max()
    values = spring_values(atoms, colour)
    springs = max(len(calc.springs), 1)
    lines = (Line3DCollection if dim == 3 else LineCollection)(
        x[calc.springs], linewidths=float(np.clip(1.2 * np.sqrt(2000 / springs), 0.15, 1.2)),
        zorder=1)
    if values is None:
        lines.set_color('0.55')
    else:
        lines.set(array=values, cmap='viridis',
                  norm=_norm([values]) if norm is None else norm)
    ax.add_collection(lines)
    if small:
        ax.scatter(*x[free].T, c='0.2', s=6, zorder=3, label='free point')
    if fixed.any():
        ax.scatter(*x[fixed].T, c='k', marker='s', s=24 if small else 4, zorder=3,
                   label='support (fixed)')
    if loaded.any():
        load = calc.potential.loads[:, columns]
        largest_load = np.linalg.norm(load[loaded], axis=1).max()
        _arrows(ax, x, load, loaded, arrow_scale(largest_load, extent * LOAD_ARROW / ARROW),
                'C1', 'load')
    largest = size[free].max(initial=0.0)
    ftol = force_tolerance(calc.potential, ftol, atoms.positions)
    if largest > ftol:
        scale = arrow_scale(largest, extent) if scale is None else scale
        _arrows(ax, x, forces, free, scale, 'C3', 'residual force')
    low, high = low[columns], high[columns]
    if dim == 3:
        ax.set(xlim=(low[0], high[0]), ylim=(low[1], high[1]), zlim=(low[2], high[2]))
        box = np.maximum(high - low, THINNEST * extent)
        ax.set_box_aspect(box, zoom=BOX_ZOOM)
        for k, axis in enumerate('xyz'):   # a thin side of the box: room for 2 ticks only
            if len(getattr(ax, f'get_{axis}ticks')()):
                getattr(ax, f'{axis}axis').set_major_locator(
                    MaxNLocator(nbins=int(np.clip(round(8 * box[k] / box.max()), 1, 4))))
    else:
        ax.set(xlim=(low[0], high[0]), ylim=(low[1], high[1]), aspect='equal')
    # inside the figure (a GIF frame is the figure, not a tight box around it)
    handles, names = ax.get_legend_handles_labels()
    if dim == 3 or tuple(columns) != (0, 1):   # a 3D net: below, inside the figure
        for old in ax.figure.legends:
            old.remove()
        ax.figure.legend(handles, names, loc='lower left', fontsize=7, framealpha=0.8)
    else:
        ax.legend(handles, names, loc='upper left', fontsize=7, framealpha=0.8)
    state = 'converged' if largest <= ftol else 'not converged'
    ax.set_title(title if title is not None else
                 f'{len(atoms)} points, {len(calc.springs)} springs, '
                 f'E = {atoms.get_potential_energy():.6g}, max |f| = {largest:.3g} '
                 f'({state}: ftol {ftol:.3g})', fontsize=9)
    return lines


def _arrows(ax: Axes, x: np.ndarray, vectors: np.ndarray, where: np.ndarray, scale: float,
            colour: str, what: str) -> None:
    """Arrows of ``vectors`` at the points ``where`` (a mask), one length
    unit per ``scale`` force units, labelled ``what`` with the scale; if
    they are more than :data:`MAX_ARROWS`, of one point in each square of a
    grid over the net's two largest extents, about :data:`MAX_ARROWS` of
    them (the legend says the square's side)."""
    points = np.flatnonzero(where)
    label = f'{what}: arrow 1 length unit = {scale:.3g} force units'
    if len(points) > MAX_ARROWS:   # one point in each cell of a grid: evenly spread
        span = np.ptp(x[points], axis=0)
        side = float(np.sqrt(np.sort(span)[-2:].prod() / MAX_ARROWS)) or span.max()
        cells = np.floor((x[points] - x[points].min(axis=0)) / side)
        points = points[np.sort(np.unique(cells, axis=0, return_index=True)[1])]
        label += f' (of one point in each {side:.3g} square)'
    arrows = vectors[points] / scale
    if x.shape[1] == 3:
        ax.quiver(*x[points].T, *arrows.T, color=colour, linewidth=0.8, label=label)
    else:
        ax.quiver(*x[points].T, *arrows.T, color=colour, angles='xy', scale_units='xy',
                  scale=1, width=0.003, zorder=2, label=label)


def _colour_bar(fig: Figure, ax: Axes, lines: LineCollection, colour: str) -> None:
    """The springs' colour bar: beside a flat picture; below a 3D view, to
    the right of the legend (beside it, a 3D axis's label or ticks would
    lie under it)."""
    if COLOURS[colour] is None:
        return
    if ax.name == '3d':
        fig.colorbar(lines, ax=ax, location='bottom', shrink=0.4, anchor=(0.95, 1.0),
                     pad=0.0, aspect=30, label=COLOURS[colour])
    else:
        fig.colorbar(lines, ax=ax, shrink=0.7, pad=0.04, label=COLOURS[colour])


def label_members(ax: Axes, atoms: Atoms, colour: str = 'force') -> None:
    """Write each spring's value (:func:`spring_values`: its force ``Q q L``
    or length, 3 significant digits) at its middle; a ValueError for more
    than :data:`MAX_LABELS` springs (unreadable) or ``colour`` 'none'."""
    values = spring_values(atoms, colour)
    springs = atoms.calc.springs
    if values is None:
        raise ValueError("labels show the springs' force or length: colour 'none' has none")
    if len(springs) > MAX_LABELS:
        raise ValueError(f'{len(springs)} springs are too many to label (at most '
                         f'{MAX_LABELS}); draw them coloured, without labels')
    columns = list(getattr(ax, 'net_columns', (0, 1, 2) if ax.name == '3d' else (0, 1)))
    middles = atoms.positions[springs].mean(axis=1)[:, columns]
    for middle, value in zip(middles, values.tolist(), strict=True):
        ax.text(*middle, f'{value:.3g}', fontsize=5, ha='center', va='center', zorder=4,
                bbox={'boxstyle': 'round,pad=0.1', 'fc': 'white', 'ec': 'none',
                      'alpha': 0.7})


def save_picture(atoms: Atoms, path: str | os.PathLike, colour: str = 'force',
                 view: str = 'iso', ftol: float | None = None,
                 title: str | None = None, labels: bool = False) -> Figure:
    """Draw the net ``atoms`` (:func:`draw`) to an image file, its format
    by the name, with each spring's value written on it if ``labels``
    (:func:`label_members`); return the figure."""
    fig, ax = figure(atoms.calc.dim, view)
    _colour_bar(fig, ax, draw(ax, atoms, colour, ftol=ftol, title=title), colour)
    if labels:
        label_members(ax, atoms, colour)
    fig.savefig(path, dpi=picture_dpi(len(atoms)), bbox_inches='tight')
    return fig


def picture_dpi(natoms: int) -> int:
    """Dots per inch of a still picture of ``natoms`` points: 110, up to
    three times that for nets of more than 10^4 points (a member about two
    pixels wide at 50,000 points, on a 7.2 inch wide figure)."""
    return int(110 * np.clip(np.sqrt(natoms) / 100, 1, 3))


def save_animation(frames: Sequence[Atoms], path: str | os.PathLike, fps: int = 8,
                   max_frames: int = 60, colour: str = 'force', view: str = 'iso',
                   ftol: float | None = None) -> int:
    """Animate a relaxation (frames of one net) to a GIF (Pillow); at most
    ``max_frames`` frames, evenly picked, first and last kept. Axes, the
    colour scale and the arrow scale are those of the whole run. Return the
    number of frames written."""
    picked = np.unique(np.linspace(0, len(frames) - 1, min(max_frames, len(frames)))
                       .round().astype(int))
    frames = [frames[i] for i in picked]
    limits = _limits(frames)
    largest = max(np.linalg.norm(a.get_forces(), axis=1).max() for a in frames)
    scale = arrow_scale(largest, (limits[1] - limits[0]).max())
    values = [spring_values(a, colour) for a in frames]
    norm = None if values[0] is None else _norm(values)
    fig, ax = figure(frames[0].calc.dim, view)
    _colour_bar(fig, ax, draw(ax, frames[0], colour, limits, norm, scale, ftol), colour)

    def update(k):
        ax.clear()
        orient(ax, view)
        draw(ax, frames[k], colour, limits, norm, scale, ftol,
             title=f'frame {picked[k]}: E = {frames[k].get_potential_energy():.6g}')

    FuncAnimation(fig, update, frames=len(frames)).save(path, writer=PillowWriter(fps=fps))
    return len(frames)


def save_disconnectivity(energies: Sequence[float], saddles: Sequence[float],
                         joins: Sequence[tuple[int, int]], path: str | os.PathLike) -> None:
    """A disconnectivity graph of minima (``energies``) joined by saddles
    (their ``saddles`` energies, ``joins`` the two minima of each): each
    minimum a vertical line from its energy up to the lowest saddle that
    joins its group to another, where the two groups' lines meet in one
    (the lower saddle first); groups never joined run to the top. Energy
    units on the y axis, minima labelled by index; any format matplotlib
    writes."""
    count = len(energies)
    group = list(range(count))          # each minimum's group (union-find root)
    bottom = {m: float(e) for m, e in enumerate(energies)}   # where its line starts
    order = sorted(range(count), key=lambda m: energies[m])
    x = {m: float(i) for i, m in enumerate(order)}   # a group's line, by its root

    def root(m):
        while group[m] != m:
            m = group[m]
        return m

    top = max([*energies, *saddles], default=0.0)
    top += 0.1 * max(top - min(energies, default=top), 1e-12)
    fig = Figure(figsize=(6, 4))
    ax = fig.add_subplot()
    for s in np.argsort(saddles):
        a, b = root(joins[s][0]), root(joins[s][1])
        if a == b:
            continue
        level = float(saddles[s])
        for r in (a, b):
            ax.plot([x[r], x[r]], [bottom[r], level], color='k', lw=1)
        ax.plot([x[a], x[b]], [level, level], color='k', lw=1)
        group[b] = a
        x[a], bottom[a] = 0.5 * (x[a] + x[b]), level
    for r in {root(m) for m in range(count)}:
        ax.plot([x[r], x[r]], [bottom[r], top], color='k', lw=1)
    for i, m in enumerate(order):
        ax.annotate(str(m), (i, energies[m]), textcoords='offset points', xytext=(0, -12),
                    ha='center', fontsize=8)
    ax.set_xticks([])
    ax.set_xlim(-1, count)
    ax.set_ylabel('energy')
    ax.set_title(f'{count} minim{"um" if count == 1 else "a"}, {len(saddles)} saddle'
                 + ('' if len(saddles) == 1 else 's'))
    fig.savefig(path, bbox_inches='tight')   # the y label kept whole
