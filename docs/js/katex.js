// Formulas typeset in the browser by KaTeX, served from js/katex/ so the site needs no
// network (also opened from file://). pymdownx.arithmatex (generic mode) wraps each
// formula as <span class="arithmatex">\(...\)</span> or <div class="arithmatex">\[...\]</div>;
// each is replaced by KaTeX's rendering, on every page Material shows (document$). The
// table of contents repeats a heading's formula as bare \(...\) text: typeset too.
//
// js/katex/ holds KaTeX 0.19.1 (MIT, its LICENSE beside it) from the npm package
// `katex`: dist/katex.min.js, dist/fonts/*.woff2 and dist/katex.min.css with the
// woff and ttf fallbacks of each @font-face removed (every browser that runs this
// site reads woff2), 0.6 MB in all, fetched by dev/katex_assets.py (a MkDocs hook)
// before the first build rather than kept in the repository.
const typeset = (tex, element, displayMode) =>
  katex.render(tex, element, { displayMode, throwOnError: false });

document$.subscribe(() => {
  for (const element of document.querySelectorAll(".arithmatex")) {
    const tex = element.textContent.trim();
    typeset(tex.slice(2, -2), element, tex.startsWith("\\["));
  }
  for (const element of document.querySelectorAll(".md-nav__link .md-ellipsis")) {
    const parts = element.textContent.split(/\\\((.+?)\\\)/);
    if (parts.length === 1) continue;
    element.replaceChildren(...parts.map((part, i) => {
      if (i % 2 === 0) return document.createTextNode(part);
      const span = document.createElement("span");
      typeset(part, span, false);
      return span;
    }));
  }
});
