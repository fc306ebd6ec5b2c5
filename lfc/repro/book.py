"""The book: the executed notebooks of the last reproduce, and the appendices in
``docs/``, as a static HTML site that works offline.

``python -m lfc book`` renders ``build/reproduce/<name>[_testbed]/<notebook>``
(executing any that are missing, incomplete — an interrupted or failed run — or
damaged, as ``reproduce`` would) with nbconvert into ``build/book/``: one page
per notebook, numbered as the notebook is (chapter 09 is ``09_multi_area.ipynb``),
its figures inline (the executed notebook holds them) and the cell papermill
injected (absolute paths) left out; one page per appendix (``docs/<name>.md``,
:data:`APPENDICES`); and ``index.html`` with the table of contents and the figure
gallery, each figure linking to its chapter, and whether the chapter's claims
were reproduced.  Every page has previous / contents / next links.  MathJax
(2.7, from the ``jupyter-server-mathjax`` package) is copied beside the pages,
so equations render with no network; nothing is fetched from a CDN.

``python -m lfc book --pdf`` also prints the whole book, in reading order, to
``build/book/lfc-scc-book.pdf`` with headless Chromium (its ``print.html``: every
page one after another, each from a new sheet), the equations typeset by the
bundled MathJax with the network blocked.
"""

from __future__ import annotations

import html
import json
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from lfc.repro import runner
from lfc.repro.manifest import CHAPTERS, chapter
from lfc.repro.notebook import PLANT_LABELS, figure_name

#: The appendices, in order: ``docs/<name>.md``, each the page ``appendix-<name>.html``
#: (a prefix no chapter's page has: chapter 11's is ``wire.html``, like an appendix).
APPENDICES = ("paper", "certified-filter", "multi-area", "coupled-certificate", "wire",
              "testbed", "guarantees", "engine", "reproducing", "parameters", "architecture")

DOCS_DIR = runner.ROOT / "docs"
#: MathJax 2.7 as the bundle has it: its combined TeX configuration, HTML-CSS output in
#: the STIX-Web fonts (the only ones bundled; MathJax's TeX fonts are not).
MATHJAX = """<script type="text/x-mathjax-config">
MathJax.Hub.Config({
  TeX: {extensions: ["AMSmath.js", "AMSsymbols.js", "noErrors.js", "noUndefined.js"],
        equationNumbers: {autoNumber: "AMS", useLabelIds: true}},
  tex2jax: {inlineMath: [["$", "$"], ["\\\\(", "\\\\)"]],
            displayMath: [["$$", "$$"], ["\\\\[", "\\\\]"]],
            processEscapes: true, processEnvironments: true},
  "HTML-CSS": {availableFonts: ["STIX"], preferredFont: "STIX", webFont: "STIX-Web",
               imageFont: null, linebreaks: {automatic: true}},
  displayAlign: "center", messageStyle: "none"
});
</script>
<script src="mathjax/MathJax.js?config=TeX-AMS-MML_HTMLorMML-full,Safe"></script>"""

STYLE = """
body { font-family: system-ui, sans-serif; max-width: 72rem; margin: 2rem auto; padding: 0 1rem;
       color: #222; }
h1 { font-size: 1.6rem; } h2 { font-size: 1.2rem; margin-top: 2rem; }
.gallery { display: grid; grid-template-columns: repeat(auto-fill, minmax(20rem, 1fr));
           gap: 1.2rem; }
figure { margin: 0; border: 1px solid #ddd; border-radius: 6px; padding: .5rem; }
figure img { width: 100%; height: auto; }
figcaption { font-size: .85rem; margin-top: .3rem; }
.ok { color: #1a7f37; } .no { color: #cf222e; }
"""

#: The lab template without what it fetches from a CDN (require.js, mermaid), with
#: the navigation above and below each page.
TEMPLATE = """{%- extends 'lab/index.html.j2' -%}
{%- block html_head_js_requirejs -%}{%- endblock html_head_js_requirejs -%}
{%- block html_head_js_mermaidjs -%}{%- endblock html_head_js_mermaidjs -%}
{%- block html_head_js_mathjax -%}""" + MATHJAX + """{%- endblock html_head_js_mathjax -%}
{%- block extra_css -%}<style>""" + """
nav.book { font-family: system-ui, sans-serif; display: flex; justify-content: space-between;
           gap: 1rem; padding: .6rem 1rem; margin: 0 auto; max-width: 72rem; font-size: .9rem; }
nav.book a { text-decoration: none; }
</style>{%- endblock extra_css -%}
{%- block body_header -%}{{ super() }}{{ resources.book_nav }}{%- endblock body_header -%}
{% block body_footer %}{{ resources.book_nav }}{{ super() }}{% endblock body_footer %}
"""

class BookError(RuntimeError):
    """Chapters that could not be executed or rendered; the rest of the book is built."""


@dataclass(frozen=True)
class Page:
    """One page of the book: ``name.html``, its title, and its source (an executed
    notebook, or an appendix's markdown)."""

    name: str
    title: str
    source: Path

    @property
    def href(self) -> str:
        return f"{self.name}.html"


def complete(executed: Path) -> bool:
    """Whether an executed notebook ran to its end without an error: readable,
    and papermill marked every code cell ``completed`` and no exception."""
    try:
        nb = json.loads(executed.read_text(encoding="utf-8"))
        if nb["metadata"].get("papermill", {}).get("exception"):
            return False
        return all(c["metadata"].get("papermill", {}).get("status") == "completed"
                   for c in nb["cells"] if c["cell_type"] == "code")
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return False


def chapter_number(notebook: str) -> str:
    """The chapter's number: its notebook's (``"09"`` for ``09_multi_area.ipynb``)."""
    return notebook.split("_", 1)[0]


def appendix_title(name: str) -> str:
    """An appendix's title: the first heading of ``docs/<name>.md``."""
    text = (DOCS_DIR / f"{name}.md").read_text(encoding="utf-8")
    return next(line[2:].strip() for line in text.splitlines() if line.startswith("# "))


def build_book(only: list[str] | None = None, build_dir: Path = runner.ROOT / "build",
               figures_dir: Path = runner.ROOT / "figures",
               appendices: tuple[str, ...] = APPENDICES, pdf: bool = False) -> Path:
    """Render the book; return the path of its ``index.html``.

    ``only``: a subset of the chapters (``lfc.repro.manifest``).  A chapter whose
    executed notebook under ``build_dir/reproduce/`` is missing or not
    :func:`complete` is executed first (figures to ``figures_dir``, as ``python
    -m lfc reproduce``).  ``appendices``: the ``docs/`` pages to include.
    ``pdf``: then print it to ``lfc-scc-book.pdf`` beside the index
    (:func:`print_pdf`).

    Raises
    ------
    BookError
        After building the rest of the book, naming each chapter that failed
        (its executed notebook and the error); its page is left out, and the
        next call executes it again.
    """
    chapters = [chapter(n) for n in only] if only else list(CHAPTERS)
    build_dir, figures_dir = Path(build_dir).resolve(), Path(figures_dir).resolve()
    out = build_dir / "book"
    (out / "figures").mkdir(parents=True, exist_ok=True)
    pages, entries, failed = [], [], []
    missing = [figure_name(c.name, plant) for c in chapters for plant in c.plants
               if not complete(build_dir / "reproduce" / figure_name(c.name, plant) / c.notebook)]
    if missing:
        print(f"book: {len(missing)} chapter run(s) have no finished notebook under "
              f"{build_dir / 'reproduce'} ({', '.join(missing)}): executing them first, as "
              f"python -m lfc reproduce would", file=sys.stderr, flush=True)
    for c in chapters:
        for plant in c.plants:
            label = figure_name(c.name, plant)
            executed = build_dir / "reproduce" / label / c.notebook
            if not complete(executed):
                outcome, = runner.reproduce([c.name], plant, jobs=1, figures_dir=figures_dir,
                                            build_dir=build_dir)
                if not complete(executed):
                    failed.append(f"{label} ({executed}): {outcome.error or 'did not finish'}")
                    (out / f"{label}.html").unlink(missing_ok=True)
                    continue
            title = f"{chapter_number(c.notebook)} · {c.title} ({PLANT_LABELS[plant]})"
            pages.append(Page(label, title, executed))
            for png in c.figure_files(plant):
                if (figures_dir / png).exists():
                    shutil.copyfile(figures_dir / png, out / "figures" / png)
            entries.append((c, plant, label, runner.read_json(executed.parent / "claims.json"),
                            runner.read_json(executed.parent / "deviations.json")))
    pages = [Page("introduction", "Introduction (the README)", runner.ROOT / "README.md"),
             *pages, *(Page(f"appendix-{name}", f"{chr(ord('A') + i)} · {appendix_title(name)}",
                            DOCS_DIR / f"{name}.md") for i, name in enumerate(appendices))]
    if len({p.name for p in pages}) < len(pages):      # one page would overwrite another
        raise ValueError(f"two pages of the book share a name: {[p.name for p in pages]}")
    names = {p.source: p for p in pages if p.source.suffix == ".md"}
    _bundle_mathjax(out)
    exporter = _exporter()
    places = {str(build_dir): "build", str(figures_dir): "figures", str(runner.ROOT): ".",
              str(Path.home()): "~"}
    for i, page in enumerate(pages):
        try:
            body = _render(exporter, page, _nav(pages, i), names, figures_dir, out)
        except Exception as err:          # nbconvert's errors name no file
            failed.append(f"{page.name} ({page.source}): cannot render: {err}")
            continue
        for place in sorted(places, key=len, reverse=True):    # no absolute path in a page
            body = body.replace(place, places[place])
        (out / page.href).write_text(body, encoding="utf-8")
    index = out / "index.html"
    index.write_text(_index(entries, pages, out), encoding="utf-8")
    if failed:
        raise BookError(f"{len(failed)} chapter(s) failed, the rest of the book is in {index}: "
                        + "; ".join(failed))
    if pdf:
        print_pdf([out / p.href for p in pages], out / PDF_NAME)
    return index


#: The book's PDF, beside its index.
PDF_NAME = "lfc-scc-book.pdf"
#: The browsers :func:`print_pdf` looks for, in order.
BROWSERS = ("chromium", "chromium-browser", "google-chrome")
#: A page of the book in print begins on a new sheet.
_SHEET = '<section style="break-before: page">{}</section>'
_NAV = re.compile(r'<nav class="book">.*?</nav>', re.S)


def print_pdf(pages: list[Path], pdf: Path, browser: str | None = None,
              timeout: float = 300.0) -> Path:
    """Print ``pages`` (the book's HTML pages, in reading order, all in one folder
    with their ``figures/`` and ``mathjax/``) to ``pdf`` with headless Chromium:
    one ``print.html`` beside them holds every page's body without its
    navigation, each from a new sheet, under the first page's head (styles and
    MathJax); Chromium runs with every host name unresolvable, so nothing is
    fetched, and gives MathJax up to 60 s of page time to typeset.

    Raises
    ------
    ValueError
        If ``pages`` is empty.
    BookError
        If no browser of :data:`BROWSERS` is installed (or ``browser`` is not an
        executable), or Chromium fails or writes no PDF.
    """
    if not pages:
        raise ValueError("pages must name at least one page of the book")
    exe = shutil.which(browser) if browser else next(
        (found for b in BROWSERS if (found := shutil.which(b))), None)
    if exe is None:
        raise BookError(f"printing the book needs Chromium ({browser or ' or '.join(BROWSERS)} "
                        "not found; on Debian: apt-get install chromium)")
    texts = [page.read_text(encoding="utf-8") for page in pages]
    bodies = [_NAV.sub("", text[re.search(r"<body[^>]*>", text).end():text.rindex("</body>")])
              for text in texts]
    first = texts[0]
    body_tag = re.search(r"<body[^>]*>", first)
    printed = pages[0].parent / "print.html"
    printed.write_text(first[:body_tag.start()] + body_tag.group(0) + bodies[0]
                       + "".join(_SHEET.format(b) for b in bodies[1:]) + "</body></html>",
                       encoding="utf-8")
    pdf = Path(pdf).resolve()
    pdf.unlink(missing_ok=True)
    done = subprocess.run([exe, "--headless", "--no-sandbox", "--disable-gpu",
                           "--no-pdf-header-footer", "--host-resolver-rules=MAP * ~NOTFOUND",
                           "--virtual-time-budget=60000", f"--print-to-pdf={pdf}",
                           printed.resolve().as_uri()],
                          capture_output=True, text=True, timeout=timeout)
    if done.returncode or not pdf.exists() or pdf.stat().st_size == 0:
        raise BookError(f"Chromium could not print {printed} (exit {done.returncode}): "
                        f"{done.stderr.strip()[-500:]}")
    return pdf


def _exporter():
    """nbconvert's HTML exporter with :data:`TEMPLATE`, the bundled MathJax, and
    the cell papermill injects (parameters with absolute paths) removed."""
    from jinja2 import DictLoader
    from nbconvert import HTMLExporter
    from nbconvert.preprocessors import TagRemovePreprocessor

    exporter = HTMLExporter(extra_loaders=[DictLoader({"book.html.j2": TEMPLATE})],
                            template_file="book.html.j2")
    exporter.register_preprocessor(TagRemovePreprocessor(
        remove_cell_tags={"injected-parameters"}, enabled=True), enabled=True)
    return exporter


def _bundle_mathjax(out: Path) -> None:
    """Copy MathJax (``jupyter_server_mathjax``'s static files) into ``out/mathjax``."""
    import jupyter_server_mathjax
    shutil.copytree(Path(jupyter_server_mathjax.__file__).parent / "static", out / "mathjax",
                    dirs_exist_ok=True)


def _nav(pages: list[Page], i: int) -> str:
    """Previous / contents / next links of page ``i``."""
    def link(j: int, arrow: str) -> str:
        if not 0 <= j < len(pages):
            return "<span></span>"
        text = f"{arrow} {pages[j].title}" if arrow == "←" else f"{pages[j].title} {arrow}"
        return f'<a href="{pages[j].href}" rel="{"prev" if arrow == "←" else "next"}">' \
               f"{html.escape(text)}</a>"
    return (f'<nav class="book">{link(i - 1, "←")}<a href="index.html">Contents</a>'
            f"{link(i + 1, '→')}</nav>")


#: A markdown link (``[text](target)``).
_LINK = re.compile(r"\[([^\]]+)\]\(([^)\s]+)\)")


def github_anchor(heading: str) -> str:
    """The anchor GitHub gives a markdown heading: lower case, punctuation dropped,
    spaces as hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _heading_id(doc: Path, slug: str) -> str:
    """The id nbconvert gives the heading of ``doc`` whose GitHub anchor is ``slug``
    (its text, spaces as hyphens); ``slug`` itself if no heading has it."""
    for head in re.findall(r"^#+ (.+)$", doc.read_text(encoding="utf-8"), re.M):
        if github_anchor(head) == slug:
            return head.strip().replace(" ", "-")
    return slug


def _page_markdown(source: Path, names: dict[Path, Page], figures_dir: Path, out: Path) -> str:
    """The README or an appendix as a book page: a link to another of them goes to
    its page (``names``: source to page; GitHub's anchors to nbconvert's
    heading ids), a figure to the book's copy, a link to any other file of the
    repository becomes its path in code (the book holds only its pages)."""
    def fix(m: re.Match) -> str:
        label, target = m.groups()
        if target.startswith(("http://", "https://", "#")):
            return m.group(0)
        path, _, anchor = target.partition("#")
        where = (source.parent / path).resolve()
        if where.parent == runner.ROOT / "figures":
            found = figures_dir / where.name if (figures_dir / where.name).exists() else where
            if found.exists():
                shutil.copyfile(found, out / "figures" / where.name)
            return f"[{label}](figures/{where.name})"
        if where in names:
            return (f"[{label}]({names[where].href}"
                    + (f"#{_heading_id(where, anchor)}" if anchor else "") + ")")
        shown = where.relative_to(runner.ROOT) if where.is_relative_to(runner.ROOT) else path
        return f"{label} (`{shown}`)"
    return _LINK.sub(fix, source.read_text(encoding="utf-8"))


def _render(exporter, page: Page, nav: str, names: dict[Path, Page], figures_dir: Path,
            out: Path) -> str:
    """The HTML of ``page``."""
    import nbformat
    if page.source.suffix == ".md":
        text = _page_markdown(page.source, names, figures_dir, out)
        nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell(text)])
    else:
        nb = nbformat.read(page.source, as_version=4)
    nb.metadata["title"] = page.title
    body, _ = exporter.from_notebook_node(nb, resources={"book_nav": nav})
    return body


def _claims_note(claims: dict[str, bool], deviations: dict[str, str]) -> str:
    """A chapter's verdict on the index: how many of its claims held, and how many
    did not as a documented deviation (its explanation as the tooltip); red only for
    a claim that failed otherwise."""
    held = sum(claims.values())
    documented = [c for c, ok in claims.items() if not ok and c in deviations]
    text = f"{held} of {len(claims)} claims reproduced"
    if documented:
        why = html.escape(" ".join(deviations[c] for c in documented), quote=True)
        text += (f', <span title="{why}">{len(documented)} a documented deviation'
                 f'{"s" if len(documented) > 1 else ""} (<a href="appendix-testbed.html">'
                 f'where the testbed differs</a>)</span>')
    ok = held + len(documented) == len(claims)
    return f'<span class="{"ok" if ok else "no"}">{text}</span>'


def _index(entries: list, pages: list[Page], out: Path) -> str:
    """The index page: the table of contents, then the gallery."""
    cards, toc = [], []
    for c, plant, label, claims, _ in entries:
        where = PLANT_LABELS[plant]
        for png in c.figure_files(plant):
            if (out / "figures" / png).exists():
                cards.append(f'<figure><a href="{label}.html"><img src="figures/{png}" '
                             f'alt="{html.escape(png)}"></a><figcaption>Chapter '
                             f"{chapter_number(c.notebook)}, <code>{html.escape(png)}</code> "
                             f"— {html.escape(c.title)} ({where})</figcaption></figure>")
    status = {label: (claims, deviations) for _, _, label, claims, deviations in entries}
    for page in pages:
        claims, deviations = status.get(page.name, (None, {}))
        note = ""
        if claims is not None:
            note = ": " + _claims_note(claims, deviations) if claims else ": no claims recorded"
        toc.append(f'<li><a href="{page.href}">{html.escape(page.title)}</a>{note}</li>')
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            "<title>lfc-scc: the book</title><style>" + STYLE + "</style></head><body>"
            "<h1>lfc-scc — a safety-critical controller for load-frequency control</h1>"
            "<p>The executed notebooks of the last <code>python -m lfc reproduce</code>: a "
            "reproduction of Mohamed, Kundur and Khalaf, <em>On the Use of Safety Critical "
            "Control for Cyber-Physical Security in the Smart Grid</em>, and what goes beyond "
            "it; then the appendices. Click a figure for its chapter.</p>"
            "<h2>Contents</h2><ul>" + "".join(toc) + "</ul>"
            "<h2>Figures</h2><div class=\"gallery\">" + "".join(cards) + "</div>"
            "</body></html>\n")
