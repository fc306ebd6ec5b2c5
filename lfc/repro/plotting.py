"""Paper-style figures: command on top, frequency or ROCOF below, relay limits dashed.

Styling and saving only: every function takes results computed elsewhere and
returns a matplotlib ``Figure``.  Nothing here chooses a backend (notebooks show
their figures inline; scripts and the runner choose their own).
"""

from __future__ import annotations

import itertools
import textwrap
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from matplotlib.ticker import NullFormatter, ScalarFormatter

from lfc._files import note_written, replace_atomic
from lfc.experiments.surface import scc_label
from lfc.relays import RelaySettings
from lfc.result import Result

TITLE_WIDTH = 90   # characters per line of a title above a legend column: longer ones wrap
FREQUENCY_RELAYS = {"OF2": "over-frequency", "UF2": "under-frequency"}
COLORS = {"a": "tab:blue", "b": "tab:orange", "c": "tab:green", "d": "tab:red",
          "no_scc": "tab:blue", "scc": "tab:orange", "scc_true": "tab:orange",
          "scc_kalman": "tab:green"}


def wrap_title(title: str, width: int = TITLE_WIDTH) -> str:
    """``title`` with each of its lines wrapped at ``width`` characters; a line break
    the caller wrote is kept (``textwrap.fill`` alone would join the lines)."""
    return "\n".join(textwrap.fill(line, width) for line in title.split("\n"))


def rocof_setting_label(relays: RelaySettings, f_nominal: float) -> str:
    """The ROCOF setting's legend entry, in pu/s and in Hz/s at ``f_nominal`` (Hz): the
    paper's settings are in pu/s, IEEE 1547's and the relays' own in Hz/s."""
    lim = relays.rocof_limit
    return f"ROCOF setting $\\pm${lim:.3g} pu/s ({lim * f_nominal:.3g} Hz/s at {f_nominal:g} Hz)"


def _limits(ax, values: list[float], label: str) -> None:
    for i, v in enumerate(values):
        ax.axhline(v, color="k", ls="--", lw=1, label=label if i == 0 else None)


def _command(ax, runs: dict[str, Result], labels: dict[str, str]) -> None:
    for key, label in labels.items():
        tr = runs[key].trace
        ax.plot(tr.t, tr.pc, color=COLORS[key], lw=1.2, label=f"{label}: $\\Delta P_c^*$")
        if runs[key].controls.scc_active.any():
            ax.plot(tr.t, tr.pc_ref, color=COLORS[key], lw=0.8, ls=":",
                    label=f"{label}: incoming $\\Delta P_c$")
    ax.set_ylabel("Governor command $\\Delta P_c$ (pu)")


def _finish(axes, title: str) -> None:
    """Time axis label, grids, legends outside the axes, title."""
    axes[-1].set_xlabel("Time (s)")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1))
    axes[0].set_title(wrap_title(title))


def _rocof(ax, runs: dict[str, Result], labels: dict[str, str], relays: RelaySettings,
           f_nominal: float, dashed: tuple[str, ...] = (), mark_trips: bool = False) -> None:
    for key, label in labels.items():
        tr = runs[key].trace
        ax.plot(tr.t, tr.rocof_meas, color=COLORS[key], lw=1.2, label=label,
                ls="--" if key in dashed else "-")
        m = runs[key].metrics() if mark_trips else {"tripped": False}
        if m["tripped"] and m["first_trip_relay"] == "ROCOF":   # the first trip, on the curve
            t = m["first_trip_t"]
            y = float(np.interp(t, tr.t, tr.rocof_meas))
            ax.plot([t], [y], marker="x", ms=9, mew=2, ls="none", color=COLORS[key],
                    label=f"{label}: ROCOF trips at {t:.2f} s")
        elif m["tripped"]:      # a frequency relay: its time only (no frequency panel here)
            t, relay = m["first_trip_t"], m["first_trip_relay"]
            ax.axvline(t, color=COLORS[key], ls=":", lw=1.5,
                       label=f"{label}: {relay} ({FREQUENCY_RELAYS[relay]}) trips at {t:.2f} s")
    _limits(ax, [relays.rocof_limit, -relays.rocof_limit], rocof_setting_label(relays, f_nominal))
    ax.set_ylabel("Measured ROCOF $\\hat{\\dot\\omega}$ (pu/s)")


def rocof_figure(runs: dict[str, Result], labels: dict[str, str], relays: RelaySettings,
                 title: str, mark_trips: bool = False, f_nominal: float = 60.0) -> Figure:
    """Command (top) and measured ROCOF (bottom, pu/s) with the ROCOF setting dashed
    (in pu/s and in Hz/s at ``f_nominal``, Hz);
    ``mark_trips``: each run's first relay trip, a ROCOF trip as a cross on its ROCOF
    curve, a frequency relay's (OF2, UF2) as a dotted line at its time."""
    fig, (top, bot) = plt.subplots(2, 1, sharex=True, figsize=(10, 6.5), layout="constrained")
    _command(top, runs, labels)
    _rocof(bot, runs, labels, relays, f_nominal, mark_trips=mark_trips)
    _finish((top, bot), title)
    return fig


def rocof_panels_figure(runs: dict[str, Result], labels: dict[str, str],
                        relays: RelaySettings, title: str, attacks: dict[str, str],
                        f_nominal: float = 60.0) -> Figure:
    """One panel per run, as the paper's Fig. 4 (a)–(d): the command (applied and,
    where the filter changed it, incoming) above the measured ROCOF (pu/s) with
    the ROCOF setting dashed and the first trip marked; ``attacks`` names each
    run's attack (its amplitude) in the panel's title.  The panels share their
    axes, so their heights compare."""
    keys = list(labels)
    cols = 2 if len(keys) > 1 else 1
    rows = -(-len(keys) // cols)
    fig = plt.figure(figsize=(13, 4.2 * rows), layout="constrained")
    grid = fig.add_gridspec(2 * rows, cols, height_ratios=[1, 1.6] * rows)
    first_cmd = first_rocof = None
    for i, key in enumerate(keys):
        r, c = divmod(i, cols)
        cmd = fig.add_subplot(grid[2 * r, c], sharex=first_cmd, sharey=first_cmd)
        roc = fig.add_subplot(grid[2 * r + 1, c], sharex=cmd, sharey=first_rocof)
        first_cmd, first_rocof = first_cmd or cmd, first_rocof or roc
        _command(cmd, runs, {key: labels[key]})
        cmd.set_ylabel("$\\Delta P_c$ (pu)")
        cmd.tick_params(labelbottom=False)
        _rocof(roc, runs, {key: labels[key]}, relays, f_nominal, mark_trips=True)
        roc.set_ylabel("ROCOF $\\hat{\\dot\\omega}$ (pu/s)")
        roc.set_xlabel("Time (s)")
        cmd.set_title(f"{labels[key]}: {attacks[key]}", fontsize=10)
        for ax in (cmd, roc):
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7, loc="best")
    fig.suptitle(title)
    return fig


def frequency_figure(runs: dict[str, Result], labels: dict[str, str],
                     relays: RelaySettings, title: str, top: str = "command",
                     f_nominal: float = 60.0) -> Figure:
    """Command or mechanical power (top) and measured frequency (bottom, pu) with OF2/UF2."""
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(10, 6.5), layout="constrained")
    if top == "command":
        _command(ax1, runs, labels)
    else:
        for key, label in labels.items():
            tr = runs[key].trace
            ax1.plot(tr.t, tr.dPm, color=COLORS[key], lw=1.2, label=label,
                     ls="-" if key == "no_scc" else "--")
        ax1.set_ylabel("Mechanical power $\\Delta P_m$ (pu)")
    _frequency(ax2, runs, labels, relays, f_nominal, () if top == "command" else ("scc",))
    _finish((ax1, ax2), title)
    return fig


def _frequency(ax, runs: dict[str, Result], labels: dict[str, str], relays: RelaySettings,
               f_nominal: float, dashed: tuple[str, ...]) -> None:
    """Measured frequency (pu) with the OF2/UF2 settings on the side(s) it moves to."""
    for key, label in labels.items():
        tr = runs[key].trace
        ax.plot(tr.t, 1 + tr.dw_meas, color=COLORS[key], lw=1.2, label=label,
                ls="--" if key in dashed else "-")
    _frequency_limits(ax, [r.trace.dw_meas for r in runs.values()], relays)
    ax.set_ylabel(f"Measured frequency $\\hat\\omega$ (pu of {f_nominal:g} Hz)")


def _frequency_limits(ax, dw: list, relays: RelaySettings) -> None:
    """OF2 / UF2 dashed, on the side(s) the deviations ``dw`` (pu) move to."""
    tiny = 1e-6  # pu: numerical noise (the testbed) does not count as moving to a side
    shown = [(n, v) for n, v, side in (("OF2", relays.of2, max(d.max() for d in dw) > tiny),
                                       ("UF2", relays.uf2, min(d.min() for d in dw) < -tiny))
             if side]
    _limits(ax, [v for _, v in shown], " / ".join(f"{n} {v:g} pu" for n, v in shown))


def fault_figure(runs: dict[str, Result], currents: dict[str, tuple[np.ndarray, np.ndarray]],
                 labels: dict[str, str], relays: RelaySettings, title: str, *,
                 f_nominal: float, line_label: str) -> Figure:
    """Fig. 7: phase-A current of the protected line (A; ``currents`` maps each run
    to its times (s) and current) with the over-current trip and breaker opening
    marked, measured frequency (pu) with OF2/UF2, and measured ROCOF (pu/s) with
    its setting.  Runs after the first are dashed; the current panel zooms on the
    fault (its own time axis)."""
    fig, axes = plt.subplots(3, 1, figsize=(10, 9), layout="constrained")
    axes[2].sharex(axes[1])
    dashed = tuple(labels)[1:]
    for key, label in labels.items():
        t, i_a = currents[key]
        axes[0].plot(t, i_a, color=COLORS[key], lw=0.6, label=label,
                     ls="--" if key in dashed else "-")
    first = runs[next(iter(labels))].line_trips
    for row in first.itertuples():
        axes[0].axvline(row.trip_t, color="k", ls=":", lw=1, label=f"{row.line} relay trips")
        axes[0].axvline(row.open_t, color="k", ls="-.", lw=1, label="breaker opens")
        axes[0].set_xlim(row.trip_t - 0.15, row.open_t + 0.15)
    axes[0].set_ylabel(f"Phase-A current, line {line_label} (A)")
    axes[0].set_xlabel("Time (s)")
    _frequency(axes[1], runs, labels, relays, f_nominal, dashed)
    _rocof(axes[2], runs, labels, relays, f_nominal, dashed)
    _finish(axes, title)
    return fig


def save_figure(fig: Figure, directory: str | Path, name: str) -> None:
    """Write ``name.png`` (150 dpi) and ``name.pdf`` with no timestamps (reproducible).

    Returns nothing, so a notebook cell that ends with it shows just the figure
    (the inline backend draws it at the end of the cell)."""
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    # through a temporary file: an interrupted or concurrent run never leaves half a figure
    replace_atomic(out / f"{name}.png", lambda tmp: fig.savefig(
        tmp, format="png", dpi=150, metadata={"Software": None}))
    replace_atomic(out / f"{name}.pdf", lambda tmp: fig.savefig(
        tmp, format="pdf", metadata={"CreationDate": None, "Creator": None, "Producer": None}))
    note_written(out / f"{name}.png")
    note_written(out / f"{name}.pdf")


TRIP_COLORS = {"none": "#eeeeee", "OF2": "tab:red", "UF2": "tab:blue", "ROCOF": "tab:orange"}


def _trip_codes(results) -> np.ndarray:
    relay = results["first_trip_relay"].fillna("none").to_numpy()
    return np.array([list(TRIP_COLORS).index(r) for r in relay])


def _trip_legend(fig: Figure) -> None:
    handles = [Patch(color=c, label="no trip" if k == "none" else f"first trip: {k}")
               for k, c in TRIP_COLORS.items()]
    fig.legend(handles=handles, loc="outside right upper", fontsize=8)


def surface_figure(results, title: str, marks: list[tuple[str, float, float, str]]) -> Figure:
    """Attack-surface maps: one panel per waveform (rows) and SCC setting
    (columns) over amplitude (pu) × frequency (Hz), each cell coloured by the
    first relay to trip.  ``marks``: (waveform, amplitude, freq_hz, label)."""
    results = results.assign(code=_trip_codes(results))
    waves = list(dict.fromkeys(results.waveform))
    alphas = list(dict.fromkeys(results.alpha.fillna(-1.0)))
    fig, axes = plt.subplots(len(waves), len(alphas), figsize=(4 * len(alphas) + 1.5,
                                                                3.4 * len(waves)),
                             sharex=True, sharey=True, squeeze=False, layout="constrained")
    cmap = ListedColormap(list(TRIP_COLORS.values()))
    amps, freqs = np.unique(results.amplitude), np.unique(results.freq_hz)
    for (i, w), (j, a) in itertools.product(enumerate(waves), enumerate(alphas)):
        ax = axes[i, j]
        sel = results[(results.waveform == w) & (results.alpha.fillna(-1.0) == a)]
        grid = sel.pivot_table(index="amplitude", columns="freq_hz", values="code",
                               aggfunc="first").reindex(index=amps, columns=freqs)
        ax.pcolormesh(_edges(freqs), _edges(amps), grid.to_numpy(), cmap=cmap, vmin=-0.5,
                      vmax=len(TRIP_COLORS) - 0.5)
        for mw, ma, mf, label in marks:
            if mw == w:
                ax.plot(mf, ma, "k*", ms=11, mfc="white")
                ax.annotate(label, (mf, ma), xytext=(5, 5), textcoords="offset points",
                            fontsize=8)
        ax.set_title(f"{w} on $P_c$, {scc_label(np.nan if a < 0 else a)}", fontsize=9)
        if i == len(waves) - 1:
            ax.set_xlabel("Attack frequency (Hz)")
        if j == 0:
            ax.set_ylabel("Attack amplitude (pu)")
    _trip_legend(fig)
    fig.suptitle(title)
    return fig


def _edges(centers: np.ndarray) -> np.ndarray:
    """Cell edges around sorted centres (for pcolormesh)."""
    c = np.asarray(centers, float)
    if len(c) == 1:
        return np.array([c[0] - 0.5, c[0] + 0.5])
    mid = (c[1:] + c[:-1]) / 2
    return np.concatenate([[c[0] - (mid[0] - c[0])], mid, [c[-1] + (c[-1] - mid[-1])]])


def bias_figure(results, relays: RelaySettings, title: str) -> Figure:
    """Bias attacks on ω_ref: first relay to trip (colour) and its time, per SCC
    setting; the bias that moves the frequency to OF2/UF2 dashed."""
    results = results.assign(code=_trip_codes(results))
    alphas = list(dict.fromkeys(results.alpha.fillna(-1.0)))
    fig, ax = plt.subplots(figsize=(10, 1.2 + 0.9 * len(alphas)), layout="constrained")
    for row, a in enumerate(alphas):
        sel = results[results.alpha.fillna(-1.0) == a]
        colors = [list(TRIP_COLORS.values())[c] for c in sel.code]
        ax.scatter(sel.amplitude, np.full(len(sel), row), c=colors, s=140, marker="s",
                   edgecolors="k", linewidths=0.3)
        for b, t in zip(sel.amplitude, sel.first_trip_t):
            if np.isfinite(t):
                ax.annotate(f"{t:.0f}", (b, row), xytext=(0, 9), textcoords="offset points",
                            ha="center", fontsize=6)
    ax.set_yticks(range(len(alphas)), [scc_label(np.nan if a < 0 else a) for a in alphas])
    ax.set_ylim(-0.7, len(alphas) - 0.3)
    _limits_v(ax, [relays.of2 - 1, relays.uf2 - 1], f"bias = OF2 − 1 / UF2 − 1 "
              f"({relays.of2 - 1:+.3g} / {relays.uf2 - 1:+.3g} pu)")
    ax.set_xlabel("Bias on the frequency reference $\\omega_{ref}$ (pu); "
                  "numbers: first trip time (s)")
    _trip_legend(fig)
    ax.legend(fontsize=8, loc="lower left")
    ax.set_title(wrap_title(title))
    return fig


def _limits_v(ax, values: list[float], label: str) -> None:
    for i, v in enumerate(values):
        ax.axvline(v, color="k", ls="--", lw=1, label=label if i == 0 else None)


def tradeoff_figure(summary, baseline, title: str) -> Figure:
    """The α–T_s trade-off.  ``summary``: one row per (event, alpha, Ts) with
    ``rocof_ratio`` and ``dw_ratio`` (peak / relay setting), ``active`` (SCC
    active fraction) and ``mean_mod`` (pu); ``baseline``: the same per event
    without SCC (dotted).  Rows: the attack, the legitimate load steps."""
    events = list(dict.fromkeys(summary.event))
    fig, axes = plt.subplots(len(events), 3, figsize=(14, 3.6 * len(events)), squeeze=False,
                             layout="constrained")
    ts_values = sorted(summary.Ts.unique())
    markers = dict(zip(ts_values, "osD^v<>"))
    cmap = plt.get_cmap("viridis")
    alphas = sorted(summary.alpha.unique())
    colors = {a: cmap(i / max(len(alphas) - 1, 1)) for i, a in enumerate(alphas)}
    cols = (("active", "rocof_ratio", "SCC active fraction", "Peak |ROCOF| / ROCOF setting"),
            ("active", "dw_ratio", "SCC active fraction", "Peak |Δω̂| / F"),
            ("mean_mod", "worst_ratio", "Mean |modification| of $\\Delta P_c$ (pu)",
             "Worst peak / relay setting"))
    for i, ev in enumerate(events):
        sel = summary[summary.event == ev]
        for j, (x, y, xl, yl) in enumerate(cols):
            ax = axes[i, j]
            for _, r in sel.iterrows():
                ax.scatter(r[x], r[y], color=colors[r.alpha], marker=markers[r.Ts], s=40,
                           edgecolors="k", linewidths=0.3)
            ax.axhline(1.0, color="k", ls="--", lw=1, label="relay setting")
            ax.axhline(baseline.loc[ev, y], color="gray", ls=":", lw=1, label="no SCC")
            ax.set_xlabel(xl)
            ax.set_ylabel(yl)
            ax.set_title(f"{ev}", fontsize=9)
            ax.grid(alpha=0.3)
    handles = [plt.Line2D([], [], color=colors[a], marker="o", ls="", label=f"α={a:g}")
               for a in alphas]
    handles += [plt.Line2D([], [], color="k", marker=markers[t], ls="", mfc="none",
                           label=f"$T_s$={t:g} s") for t in ts_values]
    handles += [plt.Line2D([], [], color="k", ls="--", label="relay setting"),
                plt.Line2D([], [], color="gray", ls=":", label="no SCC")]
    fig.legend(handles=handles, loc="outside right upper", fontsize=8)
    fig.suptitle(title)
    return fig


def severity_figure(red, title: str) -> Figure:
    """Red-team results: worst severity found per search (groups) and defender
    (bars), log scale, the relay setting (severity 1) dashed."""
    searches = list(dict.fromkeys(red.search))
    defenders = list(dict.fromkeys(red.defender))
    fig, ax = plt.subplots(figsize=(12, 4.8), layout="constrained")
    width = 0.8 / len(defenders)
    x = np.arange(len(searches))
    for i, d in enumerate(defenders):
        sel = red[red.defender == d].set_index("search").reindex(searches)
        ax.bar(x + (i - (len(defenders) - 1) / 2) * width, sel.severity, width, label=d)
    ax.axhline(1.0, color="k", ls="--", lw=1, label="relay setting (severity 1)")
    ax.set_yscale("log")
    ax.set_xticks(x, searches, rotation=15, ha="right", fontsize=8)
    ax.set_ylabel("Severity: max(|ROCOF| / setting, |Δω̂| / F)")
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1))
    ax.set_title(wrap_title(title))
    return fig


def load_bound_figure(table, title: str) -> Figure:
    """The load-during-attack trade-off (:func:`lfc.experiments.load_during_attack.tradeoff`)
    per ``load_bound``: runs of the battery that trip and that flag ``outside``
    (left, the battery's size dashed), and the time a legitimate step of the bound
    takes to be restored with and without the filter (right; never: not plotted)."""
    labels = [f"{b:g}" for b in table.load_bound]
    x = np.arange(len(table))
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.2), layout="constrained")
    left.bar(x - 0.2, table.trips, 0.4, color="tab:red", label="runs that trip")
    left.bar(x + 0.2, table.outside_runs, 0.4, color="tab:gray", label="runs flagging outside")
    left.plot(x, table.runs, "k--", lw=1, marker="_", ms=20, label="runs in the battery")
    left.set_xticks(x, labels)
    left.set_xlabel("load_bound (pu)")
    left.set_ylabel("runs (load step during an attack)")
    left.legend(fontsize=8)
    right.bar(x - 0.2, table.recovery_s, 0.4, color="tab:green", label="certified filter")
    right.bar(x + 0.2, table.recovery_s_no_filter, 0.4, color="tab:blue", label="no filter")
    for i in np.flatnonzero(np.isnan(table.recovery_s.to_numpy(float))):
        right.annotate("never", (x[i] - 0.2, 0), ha="center", va="bottom", color="tab:green")
    right.set_xticks(x, labels)
    right.set_xlabel("load_bound (pu); legitimate step of that size (0.1 pu at 0)")
    right.set_ylabel("time until |Δω| stays < 1e-3 pu (s)")
    right.legend(fontsize=8)
    for ax in (left, right):
        ax.grid(alpha=0.3, axis="y")
    fig.suptitle(title)
    return fig


def readings_figure(summary, title: str) -> Figure:
    """The paper's filter at each reading (rows) and alpha (bars): attacks of the
    maps stopped (left; the number that trip without SCC dashed) and false alarms
    on legitimate load steps (right, control periods with an alarm).  ``summary``
    is :func:`lfc.experiments.surface.readings_summary`; the default reading is marked."""
    readings = list(dict.fromkeys(summary.reading))
    alphas = sorted(summary.alpha.unique())
    fig, (left, right) = plt.subplots(1, 2, figsize=(13, 0.45 * len(readings) + 2),
                                      sharey=True, layout="constrained")
    height = 0.8 / len(alphas)
    y = np.arange(len(readings))
    for i, a in enumerate(alphas):
        sel = summary[summary.alpha == a].set_index("reading").reindex(readings)
        offset = (i - (len(alphas) - 1) / 2) * height
        left.barh(y + offset, sel.stopped, height, label=f"α = {a:g}")
        right.barh(y + offset, sel["load-step alarms"], height, label=f"α = {a:g}")
    total = int(summary["of tripping"].iloc[0])
    left.axvline(total, color="k", ls="--", lw=1, label=f"trip without SCC ({total})")
    default = summary[summary.default].reading.iloc[0]
    labels = [f"{r}  (default)" if r == default else r for r in readings]
    left.set_yticks(y, labels, fontsize=8)
    left.invert_yaxis()
    left.set_xlabel("Tripping attacks stopped (of the maps' sinusoids, squares and biases)")
    if (summary["load-step alarms"] > 0).any():      # a log scale needs a positive bar
        right.set_xscale("log")
        right.set_xlabel("False alarms on legitimate load steps (control periods, log scale)")
    else:
        right.set_xlabel("False alarms on legitimate load steps (control periods): none")
    left.set_ylabel("Reading: outside (E9) / conflict (E10) / prediction (E5)")
    for ax in (left, right):
        ax.grid(alpha=0.3, axis="x")
        ax.legend(fontsize=8, loc="lower right")
    fig.suptitle(title)
    return fig


def box_figure(worst, limit_label: str, title: str) -> Figure:
    """Worst severity per plant of a parameter box against each filter:
    ``worst`` has columns ``filter``, ``M`` (s), ``kind`` ("design", "corner",
    "interior") and ``severity``; plants by inertia on x, the relay setting
    (severity 1) dashed."""
    fig, ax = plt.subplots(figsize=(9, 4.5), layout="constrained")
    markers = {"design": "*", "corner": "o", "interior": "x"}
    for i, (name, sel) in enumerate(worst.groupby("filter", sort=False)):
        color = f"C{i}"
        for kind, part in sel.groupby("kind", sort=False):
            jitter = (i - 0.5) * 0.02
            ax.scatter(part.M + jitter, part.severity, color=color, marker=markers[kind],
                       s=60 if kind == "design" else 25, label=f"{name}, {kind} plant"
                       + ("s" if kind != "design" else ""))
    ax.axhline(1.0, color="k", ls="--", lw=1, label=limit_label)
    ax.set_xlabel("Inertia M of the plant (s)")
    ax.set_ylabel("Worst severity over the attacks:\nmax(|ROCOF| / setting, |Δω̂| / F)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1))
    ax.set_title(wrap_title(title))
    return fig


AREA_STYLES = ("-", "--", ":")


def areas_figure(runs: dict, labels: dict[str, str], relays: RelaySettings, title: str,
                 panels: tuple[str, ...] = ("command", "frequency", "rocof"),
                 f_nominal: float = 60.0) -> Figure:
    """An interconnected grid: each run (a :class:`~lfc.Result`,
    its colour) and each area (its line style), one panel per quantity in
    ``panels`` — ``"command"`` (applied ΔP_c, pu), ``"frequency"`` (pu, OF2/UF2
    dashed on the side it moves to), ``"rocof"`` (pu/s, the setting dashed),
    ``"tie"`` (tie-line export deviation, pu)."""
    fig, axes = plt.subplots(len(panels), 1, sharex=True, figsize=(10, 2.6 * len(panels)),
                             layout="constrained")
    axes = np.atleast_1d(axes)
    colors = dict(zip(labels, ("tab:blue", "tab:orange", "tab:green", "tab:red",
                              "tab:purple")))
    column = {"command": "pc", "frequency": "dw_meas", "rocof": "rocof_meas", "tie": "p_tie"}
    ylabel = {"command": "Applied command $\\Delta P_c^*$ (pu)",
              "frequency": f"Measured frequency $\\hat\\omega$ (pu of {f_nominal:g} Hz)",
              "rocof": "Measured ROCOF $\\hat{\\dot\\omega}$ (pu/s)",
              "tie": "Tie-line export $\\Delta P_{tie}$ (pu)"}
    for ax, panel in zip(axes, panels):
        moved = []
        for key, label in labels.items():
            tr = runs[key].trace
            for a in range(len(runs[key].areas)):
                y = tr[f"{column[panel]}_{a}"]
                moved.append(y)
                ax.plot(tr.t, 1 + y if panel == "frequency" else y, color=colors[key],
                        ls=AREA_STYLES[a % len(AREA_STYLES)], lw=1.1,
                        label=f"{label}, area {a}")
        if panel == "frequency":
            _frequency_limits(ax, moved, relays)
        elif panel == "rocof":
            _limits(ax, [relays.rocof_limit, -relays.rocof_limit],
                    rocof_setting_label(relays, f_nominal))
        ax.set_ylabel(ylabel[panel])
    _finish(axes, title)
    return fig


def scaling_figure(table, title: str, load_step: float = 0.05) -> Figure:
    """How two grid certificates' conservatism grows: one row of panels against
    the number of areas (``table.axis == "areas"``), one against the tie-lines'
    synchronizing coefficient (``"tie"``, log scale); columns: the contract's
    smallest box (pu, with ``load_step`` dashed: a load AGC must follow), its
    smallest rate (pu/s), and the share of each relay limit the coupled
    certificate's tightenings take (%).  ``table`` has columns ``axis``, ``x``,
    ``box``, ``rate``, ``coupled_frequency``, ``coupled_rocof`` (fractions; NaN
    where that certificate does not build: no point there)."""
    fig, axes = plt.subplots(2, 3, figsize=(12, 6.5), layout="constrained")
    xlabels = {"areas": "Number of areas (a chain, T = 2 pu)",
               "tie": "Tie-line coefficient $T$ (pu, two areas)"}
    for row, (axis, xlabel) in zip(axes, xlabels.items()):
        part = table[table.axis == axis].sort_values("x")
        row[0].plot(part.x, part.box, "o-", color="tab:purple", label="contract: box $a$")
        row[0].axhline(load_step, color="k", ls="--", lw=1,
                       label=f"a {load_step:g} pu load step AGC must follow")
        row[0].set_ylabel("Smallest box $\\pm a$ (pu)")
        row[1].plot(part.x, part.rate, "o-", color="tab:purple", label="contract: rate $r$")
        row[1].set_ylabel("Smallest rate $r$ (pu/s)")
        row[2].plot(part.x, 100 * part.coupled_frequency, "o-", color="tab:red",
                    label="coupled: frequency limit")
        row[2].plot(part.x, 100 * part.coupled_rocof, "s--", color="tab:red",
                    label="coupled: ROCOF limit")
        row[2].set_ylabel("Limit taken by tightenings (%)")
        for ax in row:
            ax.set_xlabel(xlabel)
            ax.grid(alpha=0.3)
            ax.set_ylim(bottom=0)
            ax.legend(fontsize=8)
            if axis == "tie":
                ax.set_xscale("log")
                ax.xaxis.set_minor_formatter(NullFormatter())
            ax.set_xticks(part.x)
            ax.xaxis.set_major_formatter(ScalarFormatter())
    fig.suptitle(wrap_title(title))
    return fig


def latency_figure(exchanges: dict, title: str) -> Figure:
    """Histograms of the round trips through the relay (ms, log count) of each run's
    command writes and report reads (``exchanges``: label -> DataFrame with
    ``write_ms`` and ``read_ms``, :attr:`lfc.wire.run.WireResult.exchanges`)."""
    fig, axes = plt.subplots(1, 2, sharey=True, figsize=(10, 3.6), layout="constrained")
    for ax, column, what in zip(axes, ("write_ms", "read_ms"),
                                ("command write (function 16)", "report read (function 4)")):
        top = max(float(ex[column].quantile(0.999)) for ex in exchanges.values())
        bins = np.linspace(0.0, top, 60)
        for label, ex in exchanges.items():
            ax.hist(ex[column].clip(upper=top), bins=bins, alpha=0.6, label=label)
        ax.set_yscale("log")
        ax.set_xlabel(f"Round trip of a {what} (ms)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("Control periods")
    axes[1].legend(fontsize=8, loc="upper right")
    fig.suptitle(title)
    return fig


SWEEP_LABELS = {
    "alpha": "Barrier gain α (1/s)", "amplitude": "Attack amplitude (pu)",
    "freq_hz": "Attack frequency (Hz)", "duration": "Simulated time (s)",
    "Ts": "SCC look-ahead $T_s$ (s)", "load_step": "Load step (pu)",
    "max_abs_rocof_meas": "Peak |ROCOF| measured (pu/s)",
    "max_abs_dw_meas": "Peak |Δω| measured (pu)", "first_trip_t": "First trip (s)",
    "final_abs_dw_meas": "|Δω| at the end (pu)", "alarms": "Alarms (control periods)",
    "active": "Filter active (control periods)",
    "max_abs_modification": "Largest change of the command (pu)",
    "mean_abs_modification": "Mean change of the command (pu)",
}


def sweep_figure(table, x: str, y: str, by: str | None = None,
                 relays: RelaySettings | None = None) -> Figure:
    """A sweep's table (``python -m lfc sweep``'s ``sweep.csv``): the metric ``y``
    against the parameter ``x``, one line per panel and value of ``by``; the relay
    setting dashed where ``y`` is a peak |ROCOF| or |Δω| (``relays``, default the
    paper's).  ``ValueError`` names a column the table does not have."""
    for role, col in (("x", x), ("y", y), ("by", by), ("the table's panel", "panel")):
        if col is not None and col not in table.columns:
            raise ValueError(f"{role}={col!r} is not a column of the sweep table; it has "
                             f"{sorted(table.columns)} (python -m lfc sweep writes it)")
    relays = relays or RelaySettings()
    fig, ax = plt.subplots(figsize=(8, 4.5), layout="constrained")
    groups = ["panel"] + ([by] if by and by != "panel" else [])
    for key, g in table.sort_values(x).groupby(groups, sort=True):
        key = key if isinstance(key, tuple) else (key,)
        label = ", ".join(f"{name} = {value:g}" if isinstance(value, float) else
                          f"{name} {value}" for name, value in zip(groups, key))
        ax.plot(g[x], g[y], marker="o", lw=1.2, label=label)
    limit = {"max_abs_rocof_meas": (relays.rocof_limit, "ROCOF relay setting"),
             "max_abs_dw_meas": (relays.F, "frequency relay setting")}.get(y)
    if limit:
        ax.axhline(limit[0], color="k", ls="--", lw=1, label=limit[1])
    ax.set_xlabel(SWEEP_LABELS.get(x, x))
    ax.set_ylabel(SWEEP_LABELS.get(y, y))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1))
    ax.set_title(f"{SWEEP_LABELS.get(y, y).split(' (')[0]} against "
                 f"{SWEEP_LABELS.get(x, x).split(' (')[0].lower()}")
    return fig


def gain_map_figure(gains: np.ndarray, rates: np.ndarray, critical: tuple[float, float],
                    title: str) -> Figure:
    """The growth rate (1/s) of a two-area grid's closed loop over the gains of a
    following load in either area (``gains``: the axis of both, pu/pu; ``rates[i, j]``
    at area 0's ``gains[j]`` and area 1's ``gains[i]``): the stability boundary
    (growth rate 0) solid, each area's own smallest destabilizing gain (``critical``,
    the other at 0) dashed."""
    fig, ax = plt.subplots(figsize=(7.5, 6), layout="constrained")
    top = float(np.max(np.abs(rates)))
    mesh = ax.pcolormesh(gains, gains, rates, cmap="RdBu_r", vmin=-top, vmax=top,
                         shading="nearest")
    fig.colorbar(mesh, ax=ax, label="Growth rate of the closed loop (1/s; > 0 unstable)")
    ax.contour(gains, gains, rates, levels=[0.0], colors="k", linewidths=1.5)
    ax.plot([], [], color="k", lw=1.5, label="stability boundary (growth rate 0)")
    ax.axvline(critical[0], color="k", ls="--", lw=1,
               label=f"area 0 alone: {critical[0]:.2f} pu/pu")
    ax.axhline(critical[1], color="k", ls=":", lw=1,
               label=f"area 1 alone: {critical[1]:.2f} pu/pu")
    ax.set_xlabel("Gain of the following load in area 0 (pu load per pu frequency)")
    ax.set_ylabel("Gain of the following load in area 1 (pu/pu)")
    ax.legend(fontsize=8, loc="upper right")
    ax.set_title(wrap_title(title, 60))
    return fig


def load_warning_figure(runs: dict[str, Result], labels: dict[str, str],
                        alarms: dict[str, dict[str, float | None]], relays: RelaySettings,
                        title: str, f_nominal: float = 60.0) -> Figure:
    """A load attack on one area, as each run's controller side saw it: the true
    load and each run's load as its filter holds it (``p_load_hat``, pu, top), the
    measured ROCOF (pu/s, bottom) with the setting dashed; each run's first trip, first
    ``outside`` and first load alarm (``alarms[key]``: ``"trip"``, ``"outside"``,
    ``"load alarm"`` times in s, or None) as vertical lines."""
    fig, (top, bot) = plt.subplots(2, 1, sharex=True, figsize=(10, 6.5), layout="constrained")
    first = next(iter(runs.values())).trace
    top.plot(first.t, first.p_load, color="k", lw=1.5, label="true load $\\Delta P_L$")
    styles = {"trip": "-", "outside": ":", "load alarm": "-."}
    for color, (key, label) in zip(("tab:blue", "tab:orange", "tab:green"), labels.items()):
        r = runs[key]
        top.step(r.controls.t, r.controls.p_load_hat, where="post", color=color, lw=1.1,
                 label=f"{label}: the load the filter holds")
        bot.plot(r.trace.t, r.trace.rocof_meas, color=color, lw=1.2, label=label)
        for what, t in alarms[key].items():
            if t is not None:
                for ax in (top, bot):
                    ax.axvline(t, color=color, ls=styles[what], lw=1.2,
                               label=f"{label}: {what} at {t:.3f} s" if ax is bot else None)
    _limits(bot, [relays.rocof_limit, -relays.rocof_limit],
            rocof_setting_label(relays, f_nominal))
    top.set_ylabel("Load $\\Delta P_L$ (pu)")
    bot.set_ylabel("Measured ROCOF $\\hat{\\dot\\omega}$ (pu/s)")
    _finish((top, bot), title)
    return fig
