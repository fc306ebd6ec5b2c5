"""The book (``python -m lfc book``): HTML pages of the executed notebooks, the README
and the appendices, and an index with the contents and the figure gallery, checked in a
real browser (headless Chromium) with the network blocked."""

import html as htmllib
import re
import shutil
import subprocess
from pathlib import Path
from urllib.parse import unquote

import matplotlib.image as mpimg
import numpy as np
import pytest

from lfc._files import _computing
from lfc.repro import runner
from lfc.repro.book import APPENDICES, build_book
from lfc.repro.cli import main
from lfc.repro.manifest import CHAPTERS

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="session")
def book(tmp_path_factory, worker_id):
    """The book of two chapters; the kalman one executed by the book itself.  Built
    once per test session: pytest-xdist's workers share it (the first builds it
    under a lock, the others wait and read it; the tests only read it)."""
    base = tmp_path_factory.getbasetemp()
    tmp = (base.parent if worker_id != "master" else base) / "book"
    with _computing(tmp):         # the package's lock for results two processes want
        if not (tmp / "built").exists():
            shutil.rmtree(tmp, ignore_errors=True)
            assert main(["reproduce", "--only", "tutorial", "--plant", "linear",
                         "--figures-dir", str(tmp / "fig"),
                         "--build-dir", str(tmp / "build")]) == 0
            index = build_book(["tutorial", "kalman"], tmp / "build", tmp / "fig")
            (tmp / "built").write_text(str(index))
    return Path((tmp / "built").read_text())


PAGES = ["introduction", "tutorial", "kalman", *(f"appendix-{a}" for a in APPENDICES)]
# the gallery's figures: the two chapters' (lfc.repro.manifest), on the linear model
GALLERY = [png for c in CHAPTERS if c.name in ("tutorial", "kalman")
           for png in c.figure_files("linear")]


@pytest.mark.long(80)
def test_the_book_has_an_index_with_the_gallery_and_a_page_per_notebook(book):
    text = book.read_text()
    assert {"tutorial_attack.png", "tutorial_barriers.png", "kalman_scc.png"} <= set(GALLERY)
    for png in GALLERY:
        assert f'src="figures/{png}"' in text and (book.parent / "figures" / png).exists()
    assert text.count("claims reproduced") == 2 and "4 of 4 claims reproduced" in text
    for page in ("tutorial.html", "kalman.html"):
        html = (book.parent / page).read_text()
        assert html.count("data:image/png;base64") >= 1        # the figures, inline
    assert (book.parent.parent / "reproduce" / "kalman" / "07_kalman.ipynb").exists()
    # contents in reading order, chapters numbered as their notebooks, captions unique
    toc = re.findall(r'<li><a href="([\w-]+)\.html">([^<]*)</a>', text)
    assert [name for name, _ in toc] == PAGES
    assert toc[1][1].startswith("01 · ") and toc[2][1].startswith("07 · ")
    assert toc[3][1].startswith("A · ") and toc[-1][1].startswith(f"{chr(64 + len(APPENDICES))} · ")
    captions = re.findall(r"<figcaption>(.*?)</figcaption>", text)
    assert len(captions) == len(GALLERY) and len(set(captions)) == len(captions)


def test_every_page_has_previous_and_next_links_in_reading_order(book):
    for i, name in enumerate(PAGES):
        page = (book.parent / f"{name}.html").read_text()
        navs = re.findall(r'<nav class="book">(.*?)</nav>', page, re.S)
        assert len(navs) == 2, name                               # above and below
        prev = re.findall(r'href="([\w-]+)\.html" rel="prev"', navs[0])
        nxt = re.findall(r'href="([\w-]+)\.html" rel="next"', navs[0])
        assert prev == ([PAGES[i - 1]] if i else []) and 'href="index.html"' in navs[0]
        assert nxt == ([PAGES[i + 1]] if i + 1 < len(PAGES) else [])


def test_no_page_holds_an_absolute_path_an_injected_cell_or_a_cdn(book, tmp_path):
    build = book.parents[1]
    for page in book.parent.glob("*.html"):
        text = page.read_text()
        for place in (str(build), str(runner.ROOT), str(Path.home()) + "/", "/tmp/"):
            assert place not in text, (page.name, place)
        assert "injected-parameters" not in text, page.name
        fetched = re.findall(r'<(?:script|link|img)[^>]+(?:src|href)="(https?://[^"]+)"', text)
        assert fetched == [], (page.name, fetched)


def test_every_link_and_image_of_the_book_resolves(book):
    """Every relative ``href`` and ``src`` names a file of the book, and every
    anchor an ``id`` on its page (the README's and appendices' cross-links)."""
    for page in book.parent.glob("*.html"):
        text = page.read_text()
        for target in re.findall(r'(?:href|src)="([^"]+)"', text):
            target = htmllib.unescape(target)
            if target.startswith(("http://", "https://", "data:", "mailto:")):
                continue
            path, _, anchor = target.partition("#")
            where = book.parent / path.split("?")[0] if path else page
            assert where.exists(), (page.name, target)
            if anchor:                   # as a browser matches: raw, then percent-decoded
                ids = set(re.findall(r'id="([^"]+)"', where.read_text()))
                assert {anchor, unquote(anchor)} & ids, (page.name, target)


BROWSER = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars"]
PROBE = ("<script>window.addEventListener('load', () => { const i = [...document.images]; "
         "document.title = 'images ' + i.filter(x => x.complete && x.naturalWidth > 0).length "
         "+ ' of ' + i.length; });</script>")


def screenshot(page, path) -> np.ndarray:
    subprocess.run([*BROWSER, f"--screenshot={path}", "--window-size=1280,1600", page.as_uri()],
                   check=True, capture_output=True, timeout=120)
    return mpimg.imread(path)


def images_loaded(page) -> str:
    """What Chromium reports after loading ``page``: 'images <decoded> of <all>'."""
    probe = page.with_name(f"probe-{page.name}")
    probe.write_text(page.read_text().replace("</body>", PROBE + "</body>"))
    try:
        dom = subprocess.run([*BROWSER, "--virtual-time-budget=10000", "--dump-dom",
                              probe.as_uri()], check=True, capture_output=True, text=True,
                             timeout=120).stdout
    finally:
        probe.unlink()
    return re.search(r"<title>(.*?)</title>", dom).group(1)


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (Debian package "
                    "'chromium'; .ci/run installs it)")
@pytest.mark.parametrize("page, n_images", [("index.html", 2), ("tutorial.html", 1)])
def test_chromium_renders_the_pages_with_their_figures(book, page, n_images, tmp_path):
    shot = screenshot(book.parent / page, tmp_path / "shot.png")
    assert shot.shape[0] >= 1000 and shot.shape[1] >= 1200
    ink = np.mean(np.any(shot[..., :3] < 0.9, axis=2))   # share of pixels that are not white
    assert ink > 0.02, f"{page} looks blank"
    status = images_loaded(book.parent / page)
    decoded, total = map(int, re.fullmatch(r"images (\d+) of (\d+)", status).groups())
    assert decoded == total >= n_images, f"{page}: {status} decoded by Chromium"


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed")
@pytest.mark.parametrize("page, n_math", [("tutorial.html", 20), ("introduction.html", 0)])
def test_chromium_offline_typesets_the_equations_with_the_bundled_mathjax(book, page, n_math):
    """No network (every host name fails to resolve): MathJax, copied beside the
    pages, typesets every equation; none is left as raw TeX or an error."""
    dom = subprocess.run([*BROWSER, "--host-resolver-rules=MAP * ~NOTFOUND",
                          "--virtual-time-budget=15000", "--dump-dom",
                          (book.parent / page).as_uri()],
                         check=True, capture_output=True, text=True, timeout=120).stdout
    typeset = dom.count('class="MathJax"') + dom.count('class="MathJax_Display"')
    assert typeset >= n_math and 'class="MathJax_Error"' not in dom
    if n_math:
        assert 'type="math/tex' in dom        # MathJax's record of each equation it read


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed")
def test_the_browser_check_sees_a_missing_figure(book, tmp_path):
    """The check above can fail: a gallery whose figure files are gone."""
    broken = tmp_path / "index.html"
    broken.write_text(book.read_text())           # figures/ is not beside it
    assert images_loaded(broken) == f"images 0 of {len(GALLERY)}"


def test_no_two_pages_of_the_full_book_share_a_file():
    """Chapter 11's page is ``wire.html``; the appendix ``docs/wire.md`` is
    ``appendix-wire.html`` (it once overwrote the chapter)."""
    from lfc.repro.notebook import figure_name
    labels = [figure_name(c.name, p) for c in CHAPTERS for p in c.plants]
    assert len(set(labels)) == len(labels) and "wire" in labels
    assert not any(label == "introduction" or label.startswith("appendix-") for label in labels)


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed")
def test_the_book_prints_to_one_pdf_with_its_equations_and_figures_offline(book):
    """``build_book(pdf=True)``'s printer: every page in reading order, one PDF, with
    the network blocked; MathJax typesets the equations (its STIX fonts are
    embedded: raw TeX would be in the text fonts only) and the figures are in it."""
    from lfc.repro.book import print_pdf
    names = [book.parent / f"{p}.html" for p in PAGES]
    pdf = print_pdf(names, book.parent / "book.pdf")
    data = pdf.read_bytes()
    assert data.startswith(b"%PDF-")
    assert len(re.findall(rb"/Type\s*/Page\b", data)) >= len(PAGES)   # each from a new sheet
    assert b"STIXMathJax_Main" in data                                  # typeset equations
    assert len(re.findall(rb"/Subtype\s*/Image", data)) >= 1            # the chapter's figure
    printed = (book.parent / "print.html").read_text()
    assert printed.count('break-before: page') == len(PAGES) - 1
    assert '<nav class="book">' not in printed and str(runner.ROOT) not in printed


def test_printing_without_a_browser_says_what_to_install(book, tmp_path):
    from lfc.repro.book import BookError, print_pdf
    with pytest.raises(BookError, match="needs Chromium.*apt-get install chromium"):
        print_pdf([book], tmp_path / "b.pdf", browser="no-such-browser-here")
    with pytest.raises(ValueError, match="pages must name at least one page"):
        print_pdf([], tmp_path / "b.pdf")


def test_the_index_shows_a_documented_deviation_as_such():
    """A chapter whose only failed claim is a documented deviation is not shown as a
    failure: "1 of 2 claims reproduced, 1 a documented deviation", its explanation as a
    tooltip, linking to where the testbed differs; a claim that failed otherwise is red."""
    from lfc.repro.book import _claims_note
    claims = {"with SCC no relay trips": False, "attack trips without SCC": True}
    note = _claims_note(claims, {"with SCC no relay trips": "OF2 trips at 1.0361 pu"})
    assert note.startswith('<span class="ok">1 of 2 claims reproduced, <span title="OF2 trips')
    assert "1 a documented deviation" in note and 'href="appendix-testbed.html"' in note
    assert _claims_note(claims, {}).startswith('<span class="no">1 of 2 claims reproduced')
