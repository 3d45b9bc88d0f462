"""Pictures of nets: points, springs and forces, as PNG or an animated GIF.

A net is an :class:`ase.Atoms` with a :class:`~ase_maud.MaudCalculator`
(``calc.springs``, ``calc.dim``). Springs are grey lines; free points are
coloured by the magnitude of their force ``|f|`` (colour bar in units of
``Q a``), with an arrow along ``f`` (the longest as long as a tenth of the
picture); fixed points (every coordinate held) are black squares.
``dim=2`` nets are drawn in their plane, others in 3D (mplot3d). Figures are
made without pyplot (:class:`matplotlib.figure.Figure`, rendered by Agg): no
display needed and no global backend changed.
"""

from __future__ import annotations

import io
import os
from collections.abc import Sequence

import numpy as np
from ase import Atoms
from matplotlib.animation import FuncAnimation, PillowWriter
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d.art3d import Line3DCollection

from .topology import fixed_atoms

#: Longest force arrow, as a fraction of the picture's largest extent.
ARROW = 0.1


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


def _limits(frames: Sequence[Atoms]) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper corners of a cube around every frame's points."""
    points = np.concatenate([atoms.positions for atoms in frames])
    low, high = points.min(axis=0), points.max(axis=0)
    centre, half = (low + high) / 2, max((high - low).max() / 2, 1e-12) * 1.1
    return centre - half, centre + half


def figure(dim: int) -> tuple[Figure, Axes]:
    """A figure with one 2D or 3D axes."""
    fig = Figure(figsize=(6.4, 5.6))
    ax = fig.add_subplot(projection='3d' if dim == 3 else None)
    return fig, ax


def draw(ax: Axes, atoms: Atoms, limits: tuple[np.ndarray, np.ndarray] | None = None,
         norm: Normalize | None = None, title: str | None = None):
    """Draw the net ``atoms`` on ``ax`` (2D axes for dim 2, else 3D);
    return the points' scatter (for a colour bar). ``limits`` (two corners)
    and ``norm`` (of ``|f|``) default to this frame's."""
    calc = atoms.calc
    dim = 3 if ax.name == '3d' else 2
    x = atoms.positions[:, :dim]
    forces = atoms.get_forces()[:, :dim]
    size = np.linalg.norm(forces, axis=1)
    fixed = fixed_atoms(atoms)
    low, high = _limits([atoms]) if limits is None else limits
    norm = Normalize(0, max(size.max(), 1e-300)) if norm is None else norm
    segments = x[calc.springs]
    lines = (Line3DCollection if dim == 3 else LineCollection)(
        segments, colors='0.6', linewidths=0.8, zorder=1)
    ax.add_collection(lines)
    free = ~fixed
    scatter = ax.scatter(*x[free].T, c=size[free], cmap='viridis', norm=norm, s=14, zorder=3)
    ax.scatter(*x[fixed].T, c='k', marker='s', s=14, zorder=3)
    scale = ARROW * (high - low).max() / max(norm.vmax, 1e-300)
    arrows = scale * forces[free]
    if dim == 3:
        ax.quiver(*x[free].T, *arrows.T, color='C3', linewidth=0.8)
        ax.set(xlim=(low[0], high[0]), ylim=(low[1], high[1]), zlim=(low[2], high[2]),
               xlabel='x', ylabel='y', zlabel='z')
    else:
        ax.quiver(*x[free].T, *arrows.T, color='C3', angles='xy', scale_units='xy',
                  scale=1, width=0.003, zorder=2)
        ax.set(xlim=(low[0], high[0]), ylim=(low[1], high[1]), xlabel='x', ylabel='y',
               aspect='equal')
    ax.set_title(title if title is not None else
                 f'{len(atoms)} points, {len(calc.springs)} springs, '
                 f'E = {atoms.get_potential_energy():.6g}, max |f| = {size.max():.3g}',
                 fontsize=9)
    return scatter


def save_picture(atoms: Atoms, path: str | os.PathLike, title: str | None = None) -> None:
    """Draw the net ``atoms`` to an image file (PNG by the name)."""
    fig, ax = figure(atoms.calc.dim)
    scatter = draw(ax, atoms, title=title)
    fig.colorbar(scatter, ax=ax, shrink=0.7, label='|f| (Q a)')
    fig.savefig(path, dpi=110)


def save_animation(frames: Sequence[Atoms], path: str | os.PathLike, fps: int = 8,
                   max_frames: int = 60) -> int:
    """Animate a relaxation (frames of one net) to a GIF (Pillow); at most
    ``max_frames`` frames, evenly picked, first and last kept. Axes and the
    colour scale of ``|f|`` are those of the whole run. Return the number of
    frames written."""
    picked = np.unique(np.linspace(0, len(frames) - 1, min(max_frames, len(frames)))
                       .round().astype(int))
    frames = [frames[i] for i in picked]
    limits = _limits(frames)
    largest = max(np.linalg.norm(a.get_forces(), axis=1).max() for a in frames)
    norm = Normalize(0, max(largest, 1e-300))
    fig, ax = figure(frames[0].calc.dim)
    fig.colorbar(draw(ax, frames[0], limits, norm), ax=ax, shrink=0.7, label='|f| (Q a)')

    def update(k):
        ax.clear()
        draw(ax, frames[k], limits, norm,
             title=f'frame {picked[k]}: E = {frames[k].get_potential_energy():.6g}')

    FuncAnimation(fig, update, frames=len(frames)).save(path, writer=PillowWriter(fps=fps))
    return len(frames)
