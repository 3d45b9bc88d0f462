"""Run the Python samples of the documentation pages that promise they run as written.

Each fenced ``python`` block of each page is run in a fresh interpreter in a scratch
directory that holds a copy of the shipped sample nets (``examples/nets``, which the
guide reads as a reader in the checkout would), so files it writes stay out of the
repository; a block that
fails or exceeds ``--timeout`` seconds is reported with its page and line. Run::

    NUMBA_NUM_THREADS=1 python dev/docs_samples.py [PAGE ...]

Default pages: ``docs/index.md``, ``docs/guide.md``, ``docs/guide_ase.md`` (the other
pages show fragments that continue a reader's own session). Exit status 1 if any
sample failed.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PAGES = ['docs/index.md', 'docs/guide.md', 'docs/guide_ase.md']
#: A fenced Python block: its body, and where it starts.
BLOCK = re.compile(r'^```python\n(.*?)^```', re.MULTILINE | re.DOTALL)


def samples(page: Path) -> list[tuple[int, str]]:
    """``(line, code)`` of every Python block of ``page`` (line of the fence, 1-based)."""
    text = page.read_text()
    return [(text.count('\n', 0, match.start()) + 1, match.group(1))
            for match in BLOCK.finditer(text)]


def run(code: str, timeout: float) -> tuple[bool, float, str]:
    """Run ``code`` in a fresh interpreter in a scratch directory with the sample
    nets: (ok, seconds, output)."""
    with tempfile.TemporaryDirectory() as scratch:
        shutil.copytree(ROOT / 'examples' / 'nets', Path(scratch) / 'examples' / 'nets')
        start = time.perf_counter()
        try:
            done = subprocess.run([sys.executable, '-c', code], cwd=scratch, text=True,
                                  capture_output=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            return False, time.perf_counter() - start, f'timed out after {timeout} s'
        return (done.returncode == 0, time.perf_counter() - start,
                done.stdout + done.stderr)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('pages', nargs='*', default=PAGES, metavar='PAGE')
    parser.add_argument('--timeout', type=float, default=300.0)
    args = parser.parse_args()
    failed = 0
    for name in args.pages:
        page = ROOT / name if not Path(name).is_absolute() else Path(name)
        for line, code in samples(page):
            ok, seconds, output = run(code, args.timeout)
            print(f'{"ok  " if ok else "FAIL"} {name}:{line} ({seconds:.1f} s)')
            if not ok:
                failed += 1
                print(output[-2000:])
    print(f'{failed} failed')
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
