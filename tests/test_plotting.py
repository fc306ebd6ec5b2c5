"""The figures' conventions (labelled axes with units, relay settings dashed,
names as the paper's panels), checked on the figure objects."""

import matplotlib

matplotlib.use("Agg")

import lfc  # noqa: E402
from lfc.repro.plotting import rocof_panels_figure  # noqa: E402


def test_fig4_has_the_papers_four_panels_with_amplitudes_trips_and_settings():
    P, relays = lfc.LFCParams(), lfc.RelaySettings()
    attack = lfc.Sinusoid(0.5, 1.0, start=1.0)
    runs = {"a": lfc.simulate(P, duration=3.0, pc_attack=attack),
            "b": lfc.simulate(P, duration=3.0, pc_attack=attack,
                              scc=lfc.SafetyFilter(P, relays, alpha=3.0)),
            "c": lfc.simulate(P, duration=3.0, pc_attack=attack,
                              scc=lfc.SafetyFilter(P, relays, alpha=20.0)),
            "d": lfc.simulate(P, duration=3.0, pc_attack=lfc.Sinusoid(0.1, 1.0, start=1.0),
                              scc=lfc.SafetyFilter(P, relays, alpha=20.0))}
    labels = {"a": "(a) no SCC", "b": "(b) SCC α=3", "c": "(c) SCC α=20",
              "d": "(d) weak attack, SCC α=20"}
    attacks = {k: f"{a} pu, 1 Hz sinusoid on $P_c$" for k, a in
               zip("abcd", ("0.5", "0.5", "0.5", "0.1"))}
    fig = rocof_panels_figure(runs, labels, relays, "Fig. 4 (linear model)", attacks)
    axes = fig.axes
    assert len(axes) == 8                                 # a command above each ROCOF
    titles = [ax.get_title() for ax in axes[::2]]
    assert titles == [f"{labels[k]}: {attacks[k]}" for k in "abcd"]
    for cmd, roc in zip(axes[::2], axes[1::2]):
        assert cmd.get_ylabel() == "$\\Delta P_c$ (pu)"
        assert roc.get_ylabel().endswith("(pu/s)") and roc.get_xlabel() == "Time (s)"
        dashed = [line.get_ydata()[0] for line in roc.get_lines() if line.get_linestyle() == "--"]
        assert sorted(dashed) == [-relays.rocof_limit, relays.rocof_limit]
        assert roc.get_ylim() == axes[1].get_ylim()       # shared: heights compare
    trips = [t for ax in axes[1::2] for t in ax.get_legend_handles_labels()[1] if "trips" in t]
    assert len(trips) == 1 and trips[0].startswith("(a) no SCC: ROCOF trips at")


def test_a_long_title_wraps_inside_the_figure():
    """The red team's replay title (125 characters) was clipped at the left."""
    from lfc.repro.plotting import rocof_figure
    P, relays = lfc.LFCParams(), lfc.RelaySettings()
    runs = {"no_scc": lfc.simulate(P, duration=1.0)}
    title = ("Worst free-form attack against the paper's SCC (α = 20), replayed (M ×1.114, "
             "D ×0.928, tau_g ×1.170, tau_t ×0.949, droop ×1.191)")
    fig = rocof_figure(runs, {"no_scc": "no SCC"}, relays, title)
    fig.canvas.draw()
    text = fig.axes[0].title
    box = text.get_window_extent(fig.canvas.get_renderer())
    assert "\n" in text.get_text() and text.get_text().replace("\n", " ") == title
    assert 0 <= box.x0 and box.x1 <= fig.bbox.width


def test_the_rocof_setting_is_printed_to_three_digits_in_pu_and_hz_per_second():
    """A newcomer's test (2026-11-28): IEEE 1547 category II's setting (2 Hz/s)
    read "±0.0333333 pu/s" in the legend; three significant digits, and the
    setting in Hz/s beside it (IEEE 1547 and the relays speak Hz/s, the paper pu/s)."""
    from lfc.repro.plotting import rocof_figure
    P = lfc.LFCParams()
    runs = {"no_scc": lfc.simulate(P, duration=1.0)}
    for relays, f_nominal, text in (
            (lfc.RelaySettings.ieee1547("II"), 60.0, "0.0333 pu/s (2 Hz/s at 60 Hz)"),
            (lfc.RelaySettings(), 60.0, "0.05 pu/s (3 Hz/s at 60 Hz)"),
            (lfc.RelaySettings(), 50.0, "0.05 pu/s (2.5 Hz/s at 50 Hz)")):
        fig = rocof_figure(runs, {"no_scc": "no SCC"}, relays, "title", f_nominal=f_nominal)
        legend = fig.axes[1].get_legend_handles_labels()[1]
        assert f"ROCOF setting $\\pm${text}" in legend


def test_a_titles_own_line_breaks_are_kept_and_each_line_wraps():
    """Chapter 01's titles put the physical knobs (M, relays, α, T_s) on a second line;
    ``textwrap.fill`` alone joined the lines into one that wrapped mid-phrase."""
    import textwrap

    from lfc.repro.plotting import TITLE_WIDTH, wrap_title
    assert wrap_title("Tutorial: an attack\nM = 4 s, T_s = 0.25 s") == \
        "Tutorial: an attack\nM = 4 s, T_s = 0.25 s"
    long = " ".join(["word"] * 40)
    wrapped = wrap_title(f"{long}\nknobs")
    assert wrapped.endswith("\nknobs") and all(len(line) <= TITLE_WIDTH
                                                for line in wrapped.split("\n"))
    assert wrap_title(long) == textwrap.fill(long, TITLE_WIDTH)   # one line: as before


def test_a_frequency_trip_is_a_dotted_line_at_its_time_not_a_cross_on_the_rocof_curve():
    """A newcomer's test: an OF2 trip was drawn as a cross on the ROCOF curve (the
    panel has no frequency), where it read as a ROCOF trip; now a dotted line at its
    time, its legend naming the relay and what it measures."""
    from lfc.repro.plotting import rocof_figure
    P, relays = lfc.LFCParams(), lfc.RelaySettings()
    runs = {"no_scc": lfc.simulate(P, duration=6.0, wref_attack=lfc.Step(0.1, start=1.0))}
    m = runs["no_scc"].metrics()
    assert m["first_trip_relay"] == "OF2"
    fig = rocof_figure(runs, {"no_scc": "no SCC"}, relays, "title", mark_trips=True)
    ax = fig.axes[1]
    handles, names = ax.get_legend_handles_labels()
    trip = [(h, n) for h, n in zip(handles, names) if "trips" in n]
    assert [n for _, n in trip] == [f"no SCC: OF2 (over-frequency) trips at "
                                    f"{m['first_trip_t']:.2f} s"]
    line = trip[0][0]
    assert line.get_linestyle() == ":" and list(line.get_xdata()) == [m["first_trip_t"]] * 2
    assert not any(h.get_marker() == "x" for h in handles)
