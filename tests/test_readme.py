"""The README and the appendices (docs/): the two commands, a README a newcomer reads in
minutes, and generated tables that match the figures they come from."""

import re

import pytest

from lfc.repro import runner
from lfc.repro.book import APPENDICES, github_anchor
from lfc.repro.notebook import documents, readme_mismatches, sync_readme

README = runner.ROOT / "README.md"


def test_readme_starts_with_the_two_commands():
    text = README.read_text()
    block = text.split("```bash\n", 1)[1].split("```", 1)[0].strip().splitlines()
    venv = "python3 -m venv .venv && . .venv/bin/activate && pip install -r environment.txt"
    assert block == [f"{venv} && python -m lfc reproduce", f"{venv} && python -m pytest"]
    assert text.index("```bash") < text.index("##")
    ci = (runner.ROOT / ".ci" / "run").read_text().splitlines()
    assert block[1] in ci            # CI runs the README's test command as written


def test_generated_tables_in_the_readme_and_docs_match_the_committed_results():
    """Each ``<!-- name:start -->`` section equals ``figures/name.md``, written by the
    notebook that computes it (``python -m lfc readme`` copies them in)."""
    docs = documents(runner.ROOT)
    assert len(docs) == 1 + len(APPENDICES)
    assert {d.name: readme_mismatches(d, runner.ROOT / "figures") for d in docs} == {
        d.name: [] for d in docs}


def test_the_readme_is_short_and_speaks_to_a_newcomer():
    """At most 250 lines; the quick start and the venv step are in it; it names no
    issue or working note; every appendix it points to exists and each is a book page."""
    text = README.read_text()
    assert len(text.splitlines()) <= 250
    assert "python3 -m venv" in text and "## Quick start" in text
    assert not re.search(r"\bissues?\b|notes §|\bnotes/", text, re.I)
    linked = set(re.findall(r"\(docs/([\w-]+)\.md", text))
    assert linked == set(APPENDICES)
    for doc in documents(runner.ROOT)[1:]:
        assert not re.search(r"\bthe issue\b|notes §|Robust issue|Proven issue", doc.read_text())


def test_every_readme_line_reads_as_reference():
    """No line of the README is longer than 400 characters (a table cell holds one short
    line; the full statements are in the appendices)."""
    long = [i + 1 for i, line in enumerate(README.read_text().splitlines()) if len(line) > 400]
    assert not long, f"README lines longer than 400 characters: {long}"


def test_every_link_between_the_readme_and_the_appendices_resolves():
    """Relative links (files and GitHub heading anchors) of the README and docs/*.md."""
    def anchors(path) -> set[str]:
        heads = re.findall(r"^#+ (.+)$", path.read_text(), re.M)
        return {github_anchor(h) for h in heads}
    for doc in documents(runner.ROOT):
        for target in re.findall(r"\]\(([^)\s]+)\)", doc.read_text()):
            if target.startswith(("http://", "https://")):
                continue
            path, _, anchor = target.partition("#")
            where = (doc.parent / path).resolve() if path else doc
            assert where.exists(), (doc.name, target)
            if anchor and where.suffix == ".md":
                assert anchor in anchors(where), (doc.name, target)


def test_sync_copies_tables_and_reports_what_changed(tmp_path):
    readme, tables = tmp_path / "README.md", tmp_path / "figures"
    tables.mkdir()
    readme.write_text("a\n<!-- t:start -->\nold\n<!-- t:end -->\nb\n")
    (tables / "t.md").write_text("| x |\n|---|\n| 1 |\n")
    assert readme_mismatches(readme, tables) == ["t"]
    assert sync_readme(readme, tables) == ["t"]
    assert readme.read_text() == "a\n<!-- t:start -->\n| x |\n|---|\n| 1 |\n<!-- t:end -->\nb\n"
    assert readme_mismatches(readme, tables) == [] and sync_readme(readme, tables) == []


def test_the_readmes_figures_are_the_manifests():
    """Every figure the manifest says a notebook writes is shown in the README, and
    the README shows no other (``lfc.repro.manifest``: one list)."""
    import re

    from lfc.repro.manifest import CHAPTERS
    shown = set(re.findall(r"figures/([\w]+\.png)", README.read_text()))
    written = {png for c in CHAPTERS for plant in c.plants for png in c.figure_files(plant)}
    assert shown == written
    assert all((runner.ROOT / "figures" / png).exists() for png in written)


def test_the_timing_sections_are_a_runs_record_and_its_table_says_what_ran(tmp_path):
    """``reproduce`` writes a full run's timing (build/reproduce/timing*.md) and
    ``python -m lfc readme`` copies it; the check never compares it (times vary)."""
    outcomes = [runner.RunOutcome("fig4", True, 12.34, {}, andes_seconds=14.0),
                runner.RunOutcome("redteam", True, 0.01, {}, cached=True)]
    text = runner.timing_table(outcomes, wall=20.0, cpu=35.0, jobs=2)
    assert "**20 s wall**, 35 s CPU; 1 notebook runs executed, 1 read back unchanged" in text
    assert "| fig4 | 12.3 | 14 | executed |" in text
    assert "| redteam | 0 | 0 | cached (unchanged) |" in text
    # ANDES' share and the floor it sets: 14 s of 35 s CPU, 7 s on 2 cores, 20 / 7
    assert ("14 s CPU, 40% of the run's; on 2 cores it alone takes at least 7 s: this run "
            "took 2.86× that floor.") in text
    assert "ANDES' own" not in runner.timing_table(outcomes[1:], 1.0, 1.0, 2)  # none ran
    readme = tmp_path / "README.md"
    readme.write_text("<!-- timing:start -->\nold\n<!-- timing:end -->\n")
    assert readme_mismatches(readme, tmp_path) == []
    assert runner.TIMING_FILES == {False: "timing.md", True: "timing_rerun.md"}


def test_the_readmes_quick_start_runs_and_stops_the_attack(tmp_path, monkeypatch):
    """The Python block under "Quick start", run as a reader would (in a folder of
    their own): the SCC keeps the Fig. 4 attack's ROCOF inside its setting and the
    run's files are written."""
    code = README.read_text().split("## Quick start", 1)[1].split("```python\n", 1)[1]
    code = code.split("```", 1)[0]
    monkeypatch.chdir(tmp_path)
    space: dict = {}
    exec(compile(code, "README.md (quick start)", "exec"), space)
    metrics = space["res"].metrics()
    assert not metrics["tripped"] and metrics["alarms"] > 0
    # what the text under the block says it prints
    text = " ".join(README.read_text().split("## Quick start", 1)[1].split("## Figures")[0].split())
    lfc = space["lfc"]
    alone = lfc.simulate(space["p"], duration=10, pc_attack=space["attack"]).metrics()
    assert alone["first_trip_relay"] == "ROCOF" and f"at {alone['first_trip_t']:.2f} s" in text
    assert f"about {round(metrics['alarms'], -1)} alarms" in text
    assert round(metrics["scc_active_fraction"], 1) == 0.5 and "about half" in text
    assert f"up to about {metrics['max_abs_modification']:.1f} pu" in text
    assert metrics["max_abs_modification"] > 0.5 and metrics["outside"] > 0
    assert {p.name for p in (tmp_path / "build" / "run").iterdir()} >= {
        "trace.csv", "controls.csv", "trips.csv", "alarms.csv", "metrics.json"}


@pytest.mark.exhaustive
def test_a_reader_goes_from_the_readme_to_a_modified_attack_without_touching_figures(tmp_path):
    """The path a newcomer takes (walked twice by an agent session that had never seen
    the project, acting as a reader: 5.5 and 2.1 minutes from the README to a modified
    attack, the second finding the README's papermill example overwrote the default
    run's results; a person's time is not measured): the README sends them to chapter
    01, whose "What to try next" gives a papermill command that changes the attack
    (a square wave, α = 3) after ``mkdir -p build``.  Run as written from a folder
    that holds the notebooks and no ``build/`` (as a fresh clone: papermill does not
    create its output's folder), it executes, writes its figure under
    ``build/figures``, changes no tracked file, and its kernel prints no warning
    (``--engine lfc``: over IPC, not TCP)."""
    import json
    import shlex
    import subprocess
    import sys

    readme = README.read_text()
    assert "notebooks/01_tutorial_cbf_lfc.ipynb" in readme.split("## Quick start", 1)[1]
    nb = json.loads((runner.NOTEBOOKS_DIR / "01_tutorial_cbf_lfc.ipynb").read_text())
    last = "".join(nb["cells"][-1]["source"])
    assert last.startswith("## What to try next")
    block = last.split("```bash\n", 1)[1].split("```", 1)[0]
    commands = block.replace("\\\n", " ").splitlines()[:2]     # mkdir, then papermill
    assert commands[0] == "mkdir -p build" and commands[1].startswith("papermill ")
    words = shlex.split(commands[1])
    assert "waveform" in words
    tracked = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                             cwd=runner.ROOT, capture_output=True, text=True).stdout
    figure = runner.ROOT / "build" / "figures" / "tutorial_attack.png"
    figure.unlink(missing_ok=True)
    # as in a fresh clone, where build/ does not exist yet: the commands run from a
    # folder that has the notebooks and nothing else
    (tmp_path / "notebooks").symlink_to(runner.NOTEBOOKS_DIR)
    subprocess.run(shlex.split(commands[0]), cwd=tmp_path, check=True)
    run = subprocess.run([sys.executable, "-m", *words], cwd=tmp_path, capture_output=True,
                         text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "--engine" in words and "IPKernelApp" not in run.stderr   # no TCP warning
    assert (tmp_path / "build" / "01.ipynb").exists()
    assert figure.stat().st_size > 10_000
    assert subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                          cwd=runner.ROOT, capture_output=True, text=True).stdout == tracked


def test_the_readmes_jupyterlab_runs_a_cell_over_ipc_without_a_kernel_warning(tmp_path):
    """``jupyter lab`` as the README starts it (plus a free port, a token, no browser,
    and ``--allow-root`` where the suite runs as root): a kernel started through
    JupyterLab's REST API runs a cell sent over its websocket, and the server's log
    holds no line of the kernel's (without the README's option the kernel warns
    there that its TCP traffic is unencrypted)."""
    import asyncio
    import json
    import os
    import shlex
    import socket
    import subprocess
    import sys
    import time
    import urllib.request
    import uuid

    from tornado.websocket import websocket_connect

    text = " ".join(README.read_text().split())
    command = re.search(r"started with `(jupyter lab [^`]+)`", text).group(1)
    words = shlex.split(command)
    assert "--KernelManager.transport=ipc" in words
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    extra = [f"--port={port}", "--no-browser", "--IdentityProvider.token=t",
             "--ServerApp.open_browser=False"] + (["--allow-root"] if os.getuid() == 0 else [])
    (tmp_path / "notebooks").symlink_to(runner.NOTEBOOKS_DIR)
    log = tmp_path / "lab.log"
    with open(log, "w") as out:
        server = subprocess.Popen([sys.executable, "-m", "jupyter", *words[1:], *extra],
                                  cwd=tmp_path, stdout=out, stderr=subprocess.STDOUT)
    base = f"http://127.0.0.1:{port}"

    async def run_cell(kernel: str) -> str:
        ws = await websocket_connect(f"ws://127.0.0.1:{port}/api/kernels/{kernel}/channels"
                                     "?token=t")
        msg_id = uuid.uuid4().hex
        ws.write_message(json.dumps({
            "header": {"msg_id": msg_id, "username": "reader",
                       "session": uuid.uuid4().hex, "msg_type": "execute_request",
                       "version": "5.3", "date": ""},
            "parent_header": {}, "metadata": {}, "channel": "shell",
            "content": {"code": "import lfc; print(lfc.__name__, 6 * 7)", "silent": False,
                        "store_history": False, "user_expressions": {},
                        "allow_stdin": False}}))
        # the cell's output, whole: the kernel may send one print as several stream
        # messages ("lfc", then " 42\n": seen once in a loaded CI run, 2026-12-06); it
        # has sent them all when it goes idle after the request
        out = []
        while True:
            reply = json.loads(await asyncio.wait_for(ws.read_message(), 60))
            if reply.get("parent_header", {}).get("msg_id") != msg_id:
                continue
            if reply["msg_type"] == "stream":
                out.append(reply["content"]["text"])
            elif reply["msg_type"] == "error":
                out.append(str(reply["content"]))
            elif (reply["msg_type"] == "status"
                  and reply["content"]["execution_state"] == "idle"):
                return "".join(out)

    try:
        for _ in range(120):
            try:
                urllib.request.urlopen(f"{base}/api?token=t", timeout=2)
                break
            except OSError:
                time.sleep(0.5)
        request = urllib.request.Request(f"{base}/api/kernels?token=t", data=b"{}",
                                         headers={"Content-Type": "application/json"})
        kernel = json.load(urllib.request.urlopen(request, timeout=60))["id"]
        reply = asyncio.run(run_cell(kernel))
        # the log as the cell ran, read before the server stops: stopped by a signal, it
        # interrupts its kernels, and a kernel may then log "KeyboardInterrupt caught"
        # (seen 4 times in about 24 runs beside another test, 2026-11-29)
        text = log.read_text()
    finally:
        server.terminate()
        server.wait(timeout=30)
    assert reply == "lfc 42\n", text[-3000:]
    assert "IPKernelApp" not in text, text[-3000:]      # the kernel printed nothing
