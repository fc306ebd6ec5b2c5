"""Paper-style figures: command on top, frequency or ROCOF below, relay limits dashed."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from lfc.relays import RelaySettings  # noqa: E402
from lfc.simulate import SimResult  # noqa: E402

COLORS = {"a": "tab:blue", "b": "tab:orange", "c": "tab:green", "d": "tab:red",
          "no_scc": "tab:blue", "scc": "tab:orange", "scc_true": "tab:orange",
          "scc_kalman": "tab:green"}


def _limits(ax, values: list[float], label: str) -> None:
    for i, v in enumerate(values):
        ax.axhline(v, color="k", ls="--", lw=1, label=label if i == 0 else None)


def _command(ax, runs: dict[str, SimResult], labels: dict[str, str]) -> None:
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
    axes[0].set_title(title)


def _rocof(ax, runs: dict[str, SimResult], labels: dict[str, str], relays: RelaySettings,
           dashed: tuple[str, ...] = ()) -> None:
    for key, label in labels.items():
        tr = runs[key].trace
        ax.plot(tr.t, tr.rocof_meas, color=COLORS[key], lw=1.2, label=label,
                ls="--" if key in dashed else "-")
    _limits(ax, [relays.rocof_limit, -relays.rocof_limit],
            f"ROCOF setting $\\pm${relays.rocof_limit:g} pu/s")
    ax.set_ylabel("Measured ROCOF $\\hat{\\dot\\omega}$ (pu/s)")


def rocof_figure(runs: dict[str, SimResult], labels: dict[str, str], relays: RelaySettings,
                 title: str) -> Figure:
    """Command (top) and measured ROCOF (bottom, pu/s) with the ROCOF setting dashed."""
    fig, (top, bot) = plt.subplots(2, 1, sharex=True, figsize=(10, 6.5), layout="constrained")
    _command(top, runs, labels)
    _rocof(bot, runs, labels, relays)
    _finish((top, bot), title)
    return fig


def frequency_figure(runs: dict[str, SimResult], labels: dict[str, str],
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


def _frequency(ax, runs: dict[str, SimResult], labels: dict[str, str], relays: RelaySettings,
               f_nominal: float, dashed: tuple[str, ...]) -> None:
    """Measured frequency (pu) with the OF2/UF2 settings on the side(s) it moves to."""
    for key, label in labels.items():
        tr = runs[key].trace
        ax.plot(tr.t, 1 + tr.dw_meas, color=COLORS[key], lw=1.2, label=label,
                ls="--" if key in dashed else "-")
    dw = [r.trace.dw_meas for r in runs.values()]
    shown = [(n, v) for n, v, side in (("OF2", relays.of2, max(d.max() for d in dw) > 0),
                                       ("UF2", relays.uf2, min(d.min() for d in dw) < 0)) if side]
    _limits(ax, [v for _, v in shown], " / ".join(f"{n} {v:g} pu" for n, v in shown))
    ax.set_ylabel(f"Measured frequency $\\hat\\omega$ (pu of {f_nominal:g} Hz)")


def fault_figure(runs: dict[str, SimResult], labels: dict[str, str], relays: RelaySettings,
                 title: str, *, f_nominal: float, i_base: float, line_label: str) -> Figure:
    """Fig. 7: phase-A current of the protected line (A) with the over-current
    trip and breaker opening marked, measured frequency (pu) with OF2/UF2, and
    measured ROCOF (pu/s) with its setting.  Runs after the first are dashed; the
    current panel zooms on the fault (its own time axis)."""
    from lfc.testbed.protection import phase_a_current

    fig, axes = plt.subplots(3, 1, figsize=(10, 9), layout="constrained")
    axes[2].sharex(axes[1])
    dashed = tuple(labels)[1:]
    for key, label in labels.items():
        tr = runs[key].trace
        t, i_a = phase_a_current(tr.t.to_numpy(), tr.i_line_re.to_numpy()
                                 + 1j * tr.i_line_im.to_numpy(), f_nominal=f_nominal,
                                 i_base=i_base)
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
    _rocof(axes[2], runs, labels, relays, dashed)
    _finish(axes, title)
    return fig


def save_figure(fig: Figure, directory: str | Path, name: str) -> list[Path]:
    """Write ``name.png`` (150 dpi) and ``name.pdf`` with no timestamps (reproducible)."""
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / f"{name}.png", out / f"{name}.pdf"]
    fig.savefig(paths[0], dpi=150, metadata={"Software": None})
    fig.savefig(paths[1], metadata={"CreationDate": None, "Creator": None, "Producer": None})
    return paths
