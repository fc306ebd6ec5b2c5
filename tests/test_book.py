"""The book (``python -m lfc book``): HTML pages of the executed notebooks and an
index with the figure gallery, checked in a real browser (headless Chromium)."""

import re
import shutil
import subprocess

import matplotlib.image as mpimg
import numpy as np
import pytest

from lfc.repro.book import build_book
from lfc.repro.cli import main

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def book(tmp_path_factory):
    """The book of two chapters; the kalman one executed by the book itself."""
    tmp = tmp_path_factory.mktemp("book")
    assert main(["reproduce", "--only", "tutorial", "--plant", "linear",
                 "--figures-dir", str(tmp / "fig"), "--build-dir", str(tmp / "build")]) == 0
    index = build_book(["tutorial", "kalman"], tmp / "build", tmp / "fig")
    return index


@pytest.mark.long(80)
def test_the_book_has_an_index_with_the_gallery_and_a_page_per_notebook(book):
    text = book.read_text()
    for png in ("tutorial_attack.png", "kalman_scc.png"):
        assert f'src="figures/{png}"' in text and (book.parent / "figures" / png).exists()
    assert text.count("claims reproduced") == 2 and "4 of 4 claims reproduced" in text
    for page in ("tutorial.html", "kalman.html"):
        html = (book.parent / page).read_text()
        assert html.count("data:image/png;base64") >= 1        # the figures, inline
    assert (book.parent.parent / "reproduce" / "kalman" / "07_kalman.ipynb").exists()


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
def test_the_browser_check_sees_a_missing_figure(book, tmp_path):
    """The check above can fail: a gallery whose figure files are gone."""
    broken = tmp_path / "index.html"
    broken.write_text(book.read_text())           # figures/ is not beside it
    assert images_loaded(broken) == "images 0 of 2"
