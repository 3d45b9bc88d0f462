"""Every chosen optimiser on every start, each run written as soon as it ends.

For each start (scene, size, seed) a tight reference run (``reference``
optimiser to ``ref_fmax``) and every compared run start from the same
positions. The reference energy ``e_ref`` of the start is the best minimum
found for it: the lowest final energy of the runs that reached their fmax
(the reference run's is the tightest; a reference run that stopped on a
saddle or failed does not count). Then every run's samples are appended to
``samples.csv`` and flushed. ``runs.csv`` holds one line per run (the
reference runs with status ``'reference'``; a compared optimiser not run on a
scene over its size limit, :func:`.optimizers.too_large`, with status
``'skipped'`` and the reason). Before the first start, every optimiser makes
a few untimed steps, so that one-off costs (numba loading its compiled
kernels) stay out of the timings.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

from ase_maud.bench.optimizers import too_large
from ase_maud.bench.runner import ENERGY, SAMPLE_FIELDS, Run, run_optimizer, run_status
from ase_maud.scenes.catalogue import build

SAMPLE_COLUMNS = ('scene', 'size', 'seed', 'optimiser', *SAMPLE_FIELDS,
                  'energy_error', 'status')
RUN_COLUMNS = ('scene', 'size', 'seed', 'natoms', 'optimiser', 'status',
               *SAMPLE_FIELDS, 'e_ref', 'error')


class Progress:
    """A one-line text progress bar on stderr (or nothing if not shown)."""

    def __init__(self, total, show):
        self.total, self.done, self.show = total, 0, show

    def __call__(self, label):
        if self.show:
            width = 30
            filled = width * self.done // self.total
            sys.stderr.write(f'\r[{"#" * filled}{"." * (width - filled)}] '
                             f'{self.done}/{self.total} {label:<48.48}')
            sys.stderr.flush()
        self.done += 1

    def close(self):
        if self.show:
            sys.stderr.write('\n')


def _run_row(run):
    """The runs.csv line of ``run``: its last sample (the number of calls
    for ``calls``), status and error."""
    last = (run.samples[-1] if len(run.samples)
            else np.full(len(SAMPLE_FIELDS), np.nan))
    return {'scene': run.scene, 'size': run.size, 'seed': run.seed,
            'natoms': run.natoms, 'optimiser': run.optimiser,
            'status': run.status, **dict(zip(SAMPLE_FIELDS, last, strict=True)),
            'calls': len(run.samples), 'e_ref': run.e_ref, 'error': run.error}


def _write_start(key, finished, reference, energy_rtol, samples_csv,
                 runs_csv):
    """Fix ``e_ref`` for one start, classify and write its runs; return the
    compared ones. ``finished`` maps (optimiser, fmax) to run_optimizer's
    result; the first entry is the reference run."""
    if not finished:
        return []
    finals = [samples[-1, ENERGY]
              for samples, converged, _ in finished.values() if converged]
    first = next(iter(finished.values()))[0]
    e_ref = min(finals) if finals else first[:, ENERGY].min()
    if not finals:
        print(f'\nwarning: no run reached its fmax on {key}; e_ref is the '
              'lowest energy seen', file=sys.stderr)
    compared = []
    for k, ((name, _), (samples, converged, error)) in enumerate(
            finished.items()):
        if k == 0:
            runs_csv.writerow(_run_row(Run(
                **key, optimiser=reference, samples=samples,
                status='reference', e_ref=e_ref, error=error)))
            continue
        status = run_status(samples, converged, error, e_ref, energy_rtol)
        run = Run(**key, optimiser=name, samples=samples, status=status,
                  e_ref=e_ref, error=error)
        samples_csv.writerows(run.rows())
        runs_csv.writerow(_run_row(run))
        compared.append(run)
    return compared


def run_suite(starts: list[tuple[str, object, int]], optimisers: list[str],
              outdir: Path, *, fmax: float = 1e-6, steps: int = 10000,
              reference: str = 'LBFGS', ref_fmax: float = 1e-9,
              energy_rtol: float = 1e-6,
              progress: bool = False) -> tuple[list[Run], bool]:
    """Run ``optimisers`` (names) on ``starts``, a non-empty list of
    (scene, size, seed).

    Writes ``samples.csv`` and ``runs.csv`` in ``outdir`` and returns
    ``(runs, interrupted)``: the list of finished compared :class:`Run`
    (the skipped ones included, with no samples) and whether a
    KeyboardInterrupt cut the suite short.
    """
    runs, interrupted = [], False
    bar = Progress(len(starts) * (len(optimisers) + 1), progress)
    with open(outdir / 'samples.csv', 'w', newline='') as fs, \
            open(outdir / 'runs.csv', 'w', newline='') as fr:
        samples_csv = csv.DictWriter(fs, SAMPLE_COLUMNS)
        runs_csv = csv.DictWriter(fr, RUN_COLUMNS)
        samples_csv.writeheader()
        runs_csv.writeheader()
        try:
            warm = build(*starts[0][:2], seed=starts[0][2])
            for name in dict.fromkeys([reference, *optimisers]):
                if not too_large(name, len(warm)):   # one-off costs, untimed
                    run_optimizer(warm, name, fmax, 3)
            for scene, size, seed in starts:
                start = build(scene, size, seed=seed)
                key = dict(scene=scene, size=size, seed=seed,
                           natoms=len(start))
                finished = {}   # optimiser: (samples, converged, error)
                skipped = [Run(**key, optimiser=name, status='skipped',
                               samples=np.empty((0, len(SAMPLE_FIELDS))),
                               error=too_large(name, len(start)))
                           for name in optimisers
                           if too_large(name, len(start))]
                try:
                    for k, (name, target) in enumerate(
                            ((reference, ref_fmax),
                             *((o, fmax) for o in optimisers))):
                        bar(f'{scene} {size} seed {seed}: {name}')
                        if k == 0 or not too_large(name, len(start)):
                            finished[name, target] = run_optimizer(
                                start, name, target, steps)
                finally:   # an interrupt keeps the runs that finished
                    runs += _write_start(key, finished, reference,
                                         energy_rtol, samples_csv, runs_csv)
                    runs_csv.writerows(map(_run_row, skipped))
                    runs += skipped
                    fs.flush()
                    fr.flush()
        except KeyboardInterrupt:
            interrupted = True
    bar.close()
    return runs, interrupted


def benchmark(starts: list[tuple[str, object, int]], optimisers: list[str],
              out: Path, levels: list[float], steps: int, reference: str,
              ref_fmax: float, energy_rtol: float, progress: bool,
              argv: list[str] | None = None) -> bool:
    """:func:`run_suite`, then the summary (CSV, markdown, overall table, PNGs)
    in ``out``; prints the markdown. Returns whether it was interrupted."""
    from ase_maud.bench import report  # here: it imports matplotlib, a second
    out.mkdir(parents=True, exist_ok=True)
    levels = sorted(levels, reverse=True)
    runs, interrupted = run_suite(
        starts, optimisers, out, fmax=levels[-1], steps=steps, reference=reference,
        ref_fmax=ref_fmax, energy_rtol=energy_rtol, progress=progress)
    if interrupted:
        print(f'interrupted: reporting the {len(runs)} finished runs', file=sys.stderr)
    if not runs:
        return interrupted
    summary = report.summarize(runs, levels)
    report.write_csv(out / 'summary.csv', summary)
    report.write_csv(out / 'overall.csv', report.overall(summary, levels))
    info = report.environment(argv)
    info['runs'] = (f'{len(runs)} of {len(starts) * len(optimisers)}'
                    + ' (interrupted)' * interrupted)
    info['reference'] = (f'lowest energy of {reference} to fmax {ref_fmax:g}; another '
                         f'minimum beyond relative {energy_rtol:g}')
    info['step budget'] = steps
    if skipped := report.skipped(runs):
        info['skipped'] = skipped
    (out / 'summary.md').write_text(report.markdown(summary, levels, info))
    report.plot_convergence(runs, out, levels)
    print((out / 'summary.md').read_text())
    return interrupted
