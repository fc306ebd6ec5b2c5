"""The book: the executed notebooks of the last reproduce as a static HTML site.

``python -m lfc book`` renders ``build/reproduce/<name>[_testbed]/<notebook>``
(executing any that are missing, incomplete — an interrupted or failed run — or
damaged, as ``reproduce`` would) with nbconvert into
``build/book/``: one page per notebook, its figures inline (the executed
notebook holds them), and ``index.html`` with the figure gallery, each figure
linking to its chapter, and whether the chapter's claims were reproduced.
"""

from __future__ import annotations

import html
import json
import shutil
from pathlib import Path

from lfc.repro import runner
from lfc.repro.manifest import CHAPTERS, chapter
from lfc.repro.notebook import PLANT_LABELS, figure_name

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


class BookError(RuntimeError):
    """Chapters that could not be executed or rendered; the rest of the book is built."""


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


def build_book(only: list[str] | None = None, build_dir: Path = runner.ROOT / "build",
               figures_dir: Path = runner.ROOT / "figures") -> Path:
    """Render the book; return the path of its ``index.html``.

    ``only``: a subset of the chapters (``lfc.repro.manifest``).  A chapter whose
    executed notebook under ``build_dir/reproduce/`` is missing or not
    :func:`complete` is executed first (figures to ``figures_dir``, as ``python
    -m lfc reproduce``).

    Raises
    ------
    BookError
        After building the rest of the book, naming each chapter that failed
        (its executed notebook and the error); its page is left out, and the
        next call executes it again.
    """
    from nbconvert import HTMLExporter

    chapters = [chapter(n) for n in only] if only else list(CHAPTERS)
    build_dir, figures_dir = Path(build_dir).resolve(), Path(figures_dir).resolve()
    out = build_dir / "book"
    (out / "figures").mkdir(parents=True, exist_ok=True)
    exporter = HTMLExporter()
    entries, failed = [], []
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
            try:
                body, _ = exporter.from_filename(str(executed))
            except Exception as err:          # nbconvert's errors name no file
                failed.append(f"{label} ({executed}): cannot render: {err}")
                continue
            (out / f"{label}.html").write_text(body, encoding="utf-8")
            for png in c.figure_files(plant):
                if (figures_dir / png).exists():
                    shutil.copyfile(figures_dir / png, out / "figures" / png)
            entries.append((c, plant, label, runner.read_json(executed.parent / "claims.json")))
    index = out / "index.html"
    index.write_text(_index(entries, out), encoding="utf-8")
    if failed:
        raise BookError(f"{len(failed)} chapter(s) failed, the rest of the book is in {index}: "
                        + "; ".join(failed))
    return index


def _index(entries: list, out: Path) -> str:
    """The index page: the gallery, then the chapters with their claims."""
    cards, rows = [], []
    for c, plant, label, claims in entries:
        where = PLANT_LABELS[plant]
        for png in c.figure_files(plant):
            if (out / "figures" / png).exists():
                cards.append(f'<figure><a href="{label}.html"><img src="figures/{png}" '
                             f'alt="{html.escape(png)}"></a><figcaption>{html.escape(c.title)}'
                             f" — {where}</figcaption></figure>")
        held = sum(claims.values())
        status = (f'<span class="{"ok" if held == len(claims) else "no"}">{held} of '
                  f"{len(claims)} claims reproduced</span>" if claims else "no claims recorded")
        rows.append(f'<li><a href="{label}.html">{html.escape(c.notebook)}</a> — '
                    f"{html.escape(c.title)} ({where}): {status}</li>")
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            "<title>lfc-scc: the book</title><style>" + STYLE + "</style></head><body>"
            "<h1>lfc-scc — a safety-critical controller for load-frequency control</h1>"
            "<p>The executed notebooks of the last <code>python -m lfc reproduce</code>: a "
            "reproduction of Mohamed, Kundur and Khalaf, <em>On the Use of Safety Critical "
            "Control for Cyber-Physical Security in the Smart Grid</em>, and what goes beyond "
            "it. Click a figure for its chapter.</p>"
            "<h2>Figures</h2><div class=\"gallery\">" + "".join(cards) + "</div>"
            "<h2>Chapters</h2><ol>" + "".join(rows) + "</ol></body></html>\n")
