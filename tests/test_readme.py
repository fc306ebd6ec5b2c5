"""The README: its two commands, and generated tables that match the figures they come from."""

from lfc.repro import runner
from lfc.repro.notebook import readme_mismatches, sync_readme

README = runner.ROOT / "README.md"


def test_readme_starts_with_the_two_commands():
    text = README.read_text()
    block = text.split("```bash\n", 1)[1].split("```", 1)[0].strip().splitlines()
    assert block == ["pip install -r environment.txt && python -m lfc reproduce",
                     "pip install -r environment.txt && python -m pytest"]
    assert text.index("```bash") < text.index("##")


def test_generated_tables_in_the_readme_match_the_committed_results():
    """Each ``<!-- name:start -->`` section equals ``figures/name.md``, written by the
    notebook that computes it (``python -m lfc readme`` copies them in)."""
    assert readme_mismatches(README, runner.ROOT / "figures") == []


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
    outcomes = [runner.RunOutcome("fig4", True, 12.34, {}),
                runner.RunOutcome("redteam", True, 0.01, {}, cached=True)]
    text = runner.timing_table(outcomes, wall=20.0, cpu=35.0, jobs=2)
    assert "**20 s wall**, 35 s CPU; 1 notebook runs executed, 1 read back unchanged" in text
    assert "| fig4 | 12.3 | executed |" in text
    assert "| redteam | 0 | cached (unchanged) |" in text
    readme = tmp_path / "README.md"
    readme.write_text("<!-- timing:start -->\nold\n<!-- timing:end -->\n")
    assert readme_mismatches(readme, tmp_path) == []
    assert runner.TIMING_FILES == {False: "timing.md", True: "timing_rerun.md"}
