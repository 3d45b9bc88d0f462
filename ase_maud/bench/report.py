"""Benchmark output: CSV files, the markdown summary and the PNG plots.

Summary cells are medians over seeds of the force calls and wall time to the
first sample with fmax <= each level (a run that ended in another minimum
counts as never reaching it), and their ratio to the best of the ASE
baselines on the same scene (``x best ASE``: below 1 is faster than all of
them). Plots are log-log, one panel per scene, one colour per optimiser (every
seed drawn; drawn on matplotlib's Agg canvas, no pyplot state); energy
errors are clipped at float64 round-off, ``eps |E_ref|``.
"""

import csv
import os
import platform
import sys
from datetime import datetime, timezone

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure

from ..threads import THREAD_VARIABLES
from .optimizers import ASE_BASELINES


def write_csv(path, rows):
    """Write a list of dicts (all with the same keys) as CSV."""
    with open(path, 'w', newline='') as fd:
        writer = csv.DictWriter(fd, list(rows[0]) if rows else [])
        writer.writeheader()
        writer.writerows(rows)


def environment(argv=None):
    """What a benchmark must state: threads, versions, machine, command."""
    import ase
    import numba
    import scipy
    return {'date': datetime.now(timezone.utc).isoformat(timespec='seconds'),
            'command': ' '.join(['ase-maud', *(argv or [])]),
            'numba_threads': numba.get_num_threads(),
            **{v: os.environ.get(v, 'unset') for v in THREAD_VARIABLES},
            'cpu_count': os.cpu_count(), 'machine': platform.platform(),
            'processor': platform.processor(),
            'python': sys.version.split()[0], 'ase': ase.__version__,
            'numpy': np.__version__, 'scipy': scipy.__version__,
            'numba': numba.__version__}


def summarize(runs, levels, baselines=ASE_BASELINES):
    """One dict per (scene, size, optimiser); see the module docstring."""
    groups = {}
    for run in runs:
        groups.setdefault((run.scene, run.size, run.optimiser), []).append(run)
    rows = []
    for (scene, size, name), group in groups.items():
        row = {'scene': scene, 'size': size, 'natoms': group[0].natoms,
               'optimiser': name, 'runs': len(group),
               'converged': sum(r.status == 'converged' for r in group)}
        for level in levels:
            calls, time_s = np.median([r.reached(level) for r in group], 0)
            row[f'calls@{level:g}'] = calls
            row[f'time_s@{level:g}'] = time_s
        rows.append(row)
    for row in rows:
        peers = [p for p in rows if p['optimiser'] in baselines
                 and (p['scene'], p['size']) == (row['scene'], row['size'])]
        for level in levels:
            for quantity in ('calls', 'time_s'):
                column = f'{quantity}@{level:g}'
                best = min((p[column] for p in peers), default=np.inf)
                row[f'{quantity}_ratio@{level:g}'] = (
                    row[column] / best if np.isfinite(best) else np.nan)
    return rows


def _cell(value, fmt):
    return fmt.format(value) if np.isfinite(value) else '—'


def _markdown(info, head, rows):
    """The environment as a list, then a table of ``rows`` (cell lists)."""
    lines = [f'- {key}: {value}' for key, value in info.items()]
    lines += ['', '| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)]
    lines += ['| ' + ' | '.join(map(str, cells)) + ' |' for cells in rows]
    return '\n'.join(lines) + '\n'


def markdown(summary, levels, info):
    """The benchmark summary (:func:`summarize`) as markdown."""
    head = ['scene', 'size', 'N', 'optimiser', 'converged']
    for level in levels:
        head += [f'calls to {level:g}', 'x best ASE',
                 f'ms to {level:g}', 'x best ASE']
    rows = []
    for row in summary:
        cells = [row['scene'], row['size'], row['natoms'], row['optimiser'],
                 f"{row['converged']}/{row['runs']}"]
        for level in levels:
            cells += [_cell(row[f'calls@{level:g}'], '{:.0f}'),
                      _cell(row[f'calls_ratio@{level:g}'], '{:.2f}'),
                      _cell(1e3 * row[f'time_s@{level:g}'], '{:.3g}'),
                      _cell(row[f'time_s_ratio@{level:g}'], '{:.2f}')]
        rows.append(cells)
    return _markdown(info, head, rows)


def backends_markdown(rows, info):
    """The backend measurements (:mod:`.backends`) as markdown."""
    head = ['backend', 'computes', 'N', 'threads', 'ms per call',
            'pairs per s', 'relative error']
    return _markdown(info, head, [
        [r['backend'], r['properties'], r['natoms'], r['threads'],
         f"{1e3 * r['time_per_call_s']:.3g}", f"{r['pairs_per_s']:.3g}",
         f"{r['rel_error']:.1e}"] for r in rows])


def _energy_error(run):
    floor = np.finfo(float).eps * abs(run.e_ref)
    return np.maximum(np.abs(run.samples[:, 3] - run.e_ref), floor)


PLOTS = {  # file name: (x column, x label, y of a run, y label)
    'fmax_vs_calls': (0, 'force calls', lambda r: r.samples[:, 2], 'fmax'),
    'fmax_vs_time': (1, 'wall time [s]', lambda r: r.samples[:, 2], 'fmax'),
    'energy_error_vs_calls': (0, 'force calls', _energy_error,
                              '|E - E_ref|'),
    'energy_error_vs_time': (1, 'wall time [s]', _energy_error,
                             '|E - E_ref|'),
}


def plot_convergence(runs, outdir, levels=()):
    """Write the four PNGs of :data:`PLOTS` in ``outdir``; return the paths.

    ``levels`` are drawn as dotted lines on the fmax plots.
    """
    panels = list(dict.fromkeys((r.scene, r.size, r.natoms) for r in runs))
    names = list(dict.fromkeys(r.optimiser for r in runs))
    colours = dict(zip(names, colormaps['tab10'].colors))
    ncols = min(3, len(panels))
    nrows = -(-len(panels) // ncols)
    paths = []
    for stem, (x, xlabel, y_of, ylabel) in PLOTS.items():
        fig = Figure(figsize=(4.2 * ncols + 1.8, 3.4 * nrows),
                     layout='constrained')
        axes = fig.subplots(nrows, ncols, squeeze=False)
        for ax, (scene, size, natoms) in zip(axes.flat, panels):
            for run in runs:
                if (run.scene, run.size) != (scene, size):
                    continue
                maud = run.optimiser.startswith('Maud')
                ax.loglog(run.samples[:, x], y_of(run), label=run.optimiser,
                          color=colours[run.optimiser], lw=1.8 if maud else 1)
            if ylabel == 'fmax':
                for level in levels:
                    ax.axhline(level, color='grey', ls=':', lw=0.8)
            ax.set(title=f'{scene} {size} (N = {natoms})', xlabel=xlabel,
                   ylabel=ylabel)
        for ax in axes.flat[len(panels):]:
            ax.axis('off')
        handles = {}
        for ax in axes.flat:
            for handle, label in zip(*ax.get_legend_handles_labels()):
                handles.setdefault(label, handle)
        fig.legend(handles.values(), handles.keys(), loc='outside right upper')
        path = outdir / f'{stem}.png'
        fig.savefig(path, dpi=110)
        paths.append(path)
    return paths


def plot_backends(rows, path, reference='numpy'):
    """Time per call against relative error (left; the reference backend has
    none) and against N (right): a colour per backend, solid for energy and
    forces, dashed with the stiffness blocks."""
    fig = Figure(figsize=(10, 4), layout='constrained')
    left, right = fig.subplots(1, 2)
    series = dict.fromkeys((r['backend'], r['properties']) for r in rows)
    colours = dict(zip(dict.fromkeys(r['backend'] for r in rows),
                       colormaps['tab10'].colors))
    for backend, properties in series:
        mine = [r for r in rows if (r['backend'], r['properties'])
                == (backend, properties)]
        n = [r['natoms'] for r in mine]
        t = [r['time_per_call_s'] for r in mine]
        style = {'marker': 'o', 'color': colours[backend],
                 'ls': '-' if properties == 'forces' else '--',
                 'label': f'{backend}, {properties}'}
        right.loglog(n, t, **style)
        if backend != reference:
            err = [r['rel_error'] for r in mine]
            left.loglog(err, t, **style)
            for e, ti, ni in zip(err, t, n):
                left.annotate(f'N={ni}', (e, ti), fontsize='x-small')
    left.set(xlabel=f'relative error vs {reference}',
             ylabel='time per call [s]')
    right.set(xlabel='N (points)', ylabel='time per call [s]')
    right.legend(fontsize='small')
    fig.savefig(path, dpi=110)
    return path
