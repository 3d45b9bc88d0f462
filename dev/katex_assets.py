"""A MkDocs hook (``hooks:`` in mkdocs.yml): KaTeX's browser files in
docs/js/katex/ before a build, fetched once from the npm registry.

The site typesets its formulas in the browser with KaTeX (docs/js/katex.js),
from files of its own so that it needs no network when read (file:// too).
Those files are KaTeX's npm package, not ours, so they are not kept in the
repository: before the first build this hook runs ``npm pack katex@VERSION``
(Node.js's npm, from the npm registry) and unpacks ``dist/katex.min.js``,
``dist/katex.min.css`` and ``dist/fonts/*.woff2`` with the package's LICENSE;
every ``@font-face`` keeps its woff2 source only (every browser that runs the
site reads woff2). Later builds find them there and fetch nothing. Without
npm the build stops with an error that says what to do.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tarfile
import tempfile
from pathlib import Path

#: The KaTeX release the site is built with.
VERSION = '0.19.1'

#: Where the site's pages load KaTeX from (mkdocs.yml: extra_javascript, extra_css).
TARGET = Path(__file__).resolve().parent.parent / 'docs' / 'js' / 'katex'

#: A fallback source of an ``@font-face`` (woff, ttf) after its woff2 one.
FALLBACK = re.compile(r',url\(fonts/[^)]+\.(?:woff|ttf)\) format\("(?:woff|truetype)"\)')


def on_pre_build(config, **kwargs) -> None:   # noqa: ARG001 (MkDocs' signature)
    """Fetch KaTeX into :data:`TARGET` unless it is there."""
    if (TARGET / 'katex.min.js').is_file():
        return
    npm = shutil.which('npm')
    if npm is None:
        raise SystemExit(f'docs: KaTeX {VERSION} is not in {TARGET} and npm (Node.js) is '
                         'not installed to fetch it: install npm, or unpack the npm package '
                         f'katex@{VERSION}\'s dist/katex.min.js, dist/katex.min.css and '
                         'dist/fonts/ there')
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run([npm, 'pack', f'katex@{VERSION}', '--silent'], cwd=tmp, check=True,
                       stdout=subprocess.DEVNULL)
        with tarfile.open(Path(tmp) / f'katex-{VERSION}.tgz') as archive:
            archive.extractall(tmp, filter='data')
        package = Path(tmp) / 'package'
        staged = Path(tmp) / 'katex'
        (staged / 'fonts').mkdir(parents=True)
        shutil.copy(package / 'dist' / 'katex.min.js', staged)
        shutil.copy(package / 'LICENSE', staged)
        css = (package / 'dist' / 'katex.min.css').read_text(encoding='utf-8')
        (staged / 'katex.min.css').write_text(FALLBACK.sub('', css), encoding='utf-8')
        for font in (package / 'dist' / 'fonts').glob('*.woff2'):
            shutil.copy(font, staged / 'fonts')
        TARGET.parent.mkdir(parents=True, exist_ok=True)
        shutil.rmtree(TARGET, ignore_errors=True)
        shutil.move(str(staged), TARGET)
