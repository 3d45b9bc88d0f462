"""Benchmark output: CSV files, the markdown summary and the PNG plots.

Summary cells are medians over seeds of the force calls, wall time and
process CPU time to the first sample with fmax <= each level (a run that
ended in another minimum counts as never reaching it), and their ratio to the
best of the ASE baselines on the same scene (``x best ASE``: below 1 is
faster than all of them; the best in each quantity separately); CPU time is
also divided by SciPy's L-BFGS-B's (``x L-BFGS-B``). :func:`overall` gives,
per optimiser, the median and the worst of these ratios over the scenes.
Skipped runs (over an optimiser's size limit) are left out. Plots are
log-log, one panel per scene, one colour per optimiser (every seed drawn;
drawn on matplotlib's Agg canvas, no pyplot state); energy errors are clipped
at float64 round-off, ``eps |E_ref|``.
"""

from __future__ import annotations

import csv
import os
import platform
import sys
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure

from ase_maud.backends import fmm
from ase_maud.bench.optimizers import ASE_BASELINES, SCIPY_BASELINE
from ase_maud.bench.runner import CALLS, ENERGY, FMAX, TIME_S, Run
from ase_maud.form.pictures import save_png
from ase_maud.threads import THREAD_VARIABLES


def write_csv(path, rows):
    """Write a list of dicts (all with the same keys) as CSV."""
    with open(path, 'w', newline='') as fd:
        writer = csv.DictWriter(fd, list(rows[0]) if rows else [])
        writer.writeheader()
        writer.writerows(rows)


def environment(argv=None):
    """What a benchmark must state: threads, versions, machine, command."""
    import ase  # here: the versions a report states
    import numba
    import scipy
    return {'date': datetime.now(timezone.utc).isoformat(timespec='seconds'),
            'command': ' '.join(['ase-maud', *(argv or [])]),
            'numba_threads': numba.get_num_threads(),
            'fmm_threads': fmm.library_threads(), 'fmm_workers': fmm.workers(),
            **{v: os.environ.get(v, 'unset') for v in THREAD_VARIABLES},
            'cpu_count': os.cpu_count(), 'machine': platform.platform(),
            'processor': platform.processor(),
            'python': sys.version.split()[0], 'ase': ase.__version__,
            'numpy': np.__version__, 'scipy': scipy.__version__,
            'numba': numba.__version__}


#: The quantities of the summary, in the order :meth:`.Run.reached` gives them.
QUANTITIES = ('calls', 'time_s', 'cpu_s')


def summarize(runs: list[Run], levels: list[float],
              baselines: tuple[str, ...] = ASE_BASELINES,
              scipy: str = SCIPY_BASELINE) -> list[dict]:
    """One dict per (scene, size, optimiser); see the module docstring.

    Columns ``<quantity>@<level>``, ``<quantity>_ratio@<level>`` (to the best
    of ``baselines``; NaN if none of them ran on the scene) and
    ``cpu_s_scipy_ratio@<level>`` (to ``scipy``; NaN if it did not run),
    for each quantity of :data:`QUANTITIES`.
    """
    groups = {}
    for run in runs:
        if run.status != 'skipped':
            groups.setdefault((run.scene, run.size, run.optimiser),
                              []).append(run)
    rows = []
    for (scene, size, name), group in groups.items():
        row = {'scene': scene, 'size': size, 'natoms': group[0].natoms,
               'optimiser': name, 'runs': len(group),
               'converged': sum(r.status == 'converged' for r in group)}
        for level in levels:
            medians = np.median([r.reached(level) for r in group], 0)
            row.update({f'{quantity}@{level:g}': value
                        for quantity, value in zip(QUANTITIES, medians, strict=True)})
        rows.append(row)
    for row in rows:
        scene = [p for p in rows
                 if (p['scene'], p['size']) == (row['scene'], row['size'])]
        peers = [p for p in scene if p['optimiser'] in baselines]
        reference = [p for p in scene if p['optimiser'] == scipy]
        for level in levels:
            for quantity in QUANTITIES:
                column = f'{quantity}@{level:g}'
                row[f'{quantity}_ratio@{level:g}'] = _ratio(
                    row[column], [p[column] for p in peers])
            column = f'cpu_s@{level:g}'
            row[f'cpu_s_scipy_ratio@{level:g}'] = _ratio(
                row[column], [p[column] for p in reference])
    return rows


def _ratio(value, baselines):
    """``value`` over the least of ``baselines``; NaN if none is finite."""
    best = min(baselines, default=np.inf)
    return value / best if np.isfinite(best) else np.nan


#: The ratio columns :func:`overall` sums up, with their markdown heads.
OVERALL = {'calls_ratio': 'calls to {} x best ASE',
           'cpu_s_ratio': 'CPU s to {} x best ASE',
           'cpu_s_scipy_ratio': 'CPU s to {} x L-BFGS-B'}


def overall(summary: list[dict], levels: list[float]) -> list[dict]:
    """Per optimiser, two dicts: the ``median`` and the ``worst`` (largest)
    over the scenes of each ratio of :data:`OVERALL` at each level.

    A scene where the ratio is NaN (no baseline to compare) is left out; one
    where the optimiser never reached the level counts as infinite.
    ``scenes`` is the number of the optimiser's scenes.
    """
    names = dict.fromkeys(row['optimiser'] for row in summary)
    rows = []
    for name in names:
        mine = [row for row in summary if row['optimiser'] == name]
        for statistic, reduce in (('median', np.median), ('worst', np.max)):
            out = {'optimiser': name, 'statistic': statistic,
                   'scenes': len(mine)}
            for level in levels:
                for ratio in OVERALL:
                    values = [row[f'{ratio}@{level:g}'] for row in mine]
                    values = [v for v in values if not np.isnan(v)]
                    out[f'{ratio}@{level:g}'] = (reduce(values) if values
                                                 else np.nan)
            rows.append(out)
    return rows


def skipped(runs: list[Run]) -> str:
    """The skipped runs, one clause each ('' if none)."""
    return '; '.join(f'{r.optimiser} on {r.scene} {r.size} ({r.error})'
                     for r in runs if r.status == 'skipped')


def _cell(value, fmt, infinite='—'):
    """``value`` formatted; ``infinite`` if it is infinite, — if NaN."""
    if np.isfinite(value):
        return fmt.format(value)
    return infinite if np.isinf(value) else '—'


def _markdown(info, head, rows):
    """The environment as a list, then a table of ``rows`` (cell lists)."""
    lines = [f'- {key}: {value}' for key, value in info.items()]
    lines += ['', *_table(head, rows)]
    return '\n'.join(lines) + '\n'


def _table(head, rows):
    """The lines of a markdown table."""
    return ['| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head),
            *('| ' + ' | '.join(map(str, cells)) + ' |' for cells in rows)]


def markdown(summary: list[dict], levels: list[float], info: dict) -> str:
    """The benchmark summary (:func:`summarize`) as markdown, then the
    median and worst ratios of each optimiser (:func:`overall`)."""
    head = ['scene', 'size', 'N', 'optimiser', 'converged']
    for level in levels:
        head += [f'calls to {level:g}', 'x best ASE',
                 f'ms to {level:g}', 'x best ASE',
                 f'CPU s to {level:g}', 'x best ASE', 'x L-BFGS-B']
    rows = []
    for row in summary:
        cells = [row['scene'], row['size'], row['natoms'], row['optimiser'],
                 f"{row['converged']}/{row['runs']}"]
        for level in levels:
            cells += [_cell(row[f'calls@{level:g}'], '{:.0f}'),
                      _cell(row[f'calls_ratio@{level:g}'], '{:.2f}'),
                      _cell(1e3 * row[f'time_s@{level:g}'], '{:.3g}'),
                      _cell(row[f'time_s_ratio@{level:g}'], '{:.2f}'),
                      _cell(row[f'cpu_s@{level:g}'], '{:.3g}'),
                      _cell(row[f'cpu_s_ratio@{level:g}'], '{:.2f}'),
                      _cell(row[f'cpu_s_scipy_ratio@{level:g}'], '{:.2f}')]
        rows.append(cells)
    head2 = ['optimiser', 'over scenes', 'scenes']
    head2 += [text.format(f'{level:g}') for level in levels
              for text in OVERALL.values()]
    rows2 = [[row['optimiser'], row['statistic'], row['scenes'],
              *(_cell(row[f'{ratio}@{level:g}'], '{:.2f}', '∞')
                for level in levels for ratio in OVERALL)]
             for row in overall(summary, levels)]
    return (_markdown(info, head, rows) + '\nOver all scenes (a level never '
            'reached on a scene counts as ∞; a scene without the baseline is '
            'left out, — if all are):\n\n' + '\n'.join(_table(head2, rows2))
            + '\n')


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
    return np.maximum(np.abs(run.samples[:, ENERGY] - run.e_ref), floor)


PLOTS = {  # file name: (x column, x label, y of a run, y label)
    'fmax_vs_calls': (CALLS, 'force calls', lambda r: r.samples[:, FMAX],
                      'fmax'),
    'fmax_vs_time': (TIME_S, 'wall time [s]', lambda r: r.samples[:, FMAX],
                     'fmax'),
    'energy_error_vs_calls': (CALLS, 'force calls', _energy_error,
                              '|E - E_ref|'),
    'energy_error_vs_time': (TIME_S, 'wall time [s]', _energy_error,
                             '|E - E_ref|'),
}


def plot_convergence(runs: list[Run], outdir: Path,
                     levels: list[float] = ()) -> list[Path]:
    """Write the four PNGs of :data:`PLOTS` in ``outdir``; return the paths.

    ``levels`` are drawn as dotted lines on the fmax plots; skipped runs are
    left out.
    """
    runs = [r for r in runs if r.status != 'skipped']
    panels = list(dict.fromkeys((r.scene, r.size, r.natoms) for r in runs))
    names = list(dict.fromkeys(r.optimiser for r in runs))
    palette = colormaps['tab10' if len(names) <= 10 else 'tab20'].colors
    colours = {name: palette[k % len(palette)] for k, name in enumerate(names)}
    ncols = min(3, len(panels))
    nrows = -(-len(panels) // ncols)
    paths = []
    for stem, (x, xlabel, y_of, ylabel) in PLOTS.items():
        fig = Figure(figsize=(4.2 * ncols + 1.8, 3.4 * nrows),
                     layout='constrained')
        axes = fig.subplots(nrows, ncols, squeeze=False)
        for ax, (scene, size, natoms) in zip(axes.flat, panels, strict=False):
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
            for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
                handles.setdefault(label, handle)
        fig.legend(handles.values(), handles.keys(), loc='outside right upper')
        path = outdir / f'{stem}.png'
        save_png(fig, path)
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
                       colormaps['tab10'].colors, strict=False))
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
            for e, ti, ni in zip(err, t, n, strict=True):
                left.annotate(f'N={ni}', (e, ti), fontsize='x-small')
    left.set(xlabel=f'relative error vs {reference}',
             ylabel='time per call [s]')
    right.set(xlabel='N (points)', ylabel='time per call [s]')
    right.legend(fontsize='small')
    save_png(fig, path)
    return path
