"""The figure manifest: every notebook (a chapter of the tutorial), the plants it
runs on, the figures it writes and the parameters of its short test runs.

Read by the runner (``python -m lfc reproduce`` and ``book``), by the tests
(``tests/test_notebooks.py`` runs each chapter with its ``short`` parameters;
``tests/test_readme.py`` checks the README's figure table against ``figures``)
— one list, so a new figure is added in one place.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from lfc.experiments.scenarios import ALL_PLANTS, PLANTS

#: the repository: ``notebooks/``, ``figures/``, ``build/``
ROOT = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Chapter:
    """One notebook.

    Attributes
    ----------
    name : str
        Short name (``--only``, build folders).
    notebook : str
        File in ``notebooks/``.
    title : str
        What the chapter shows (the book's index).
    plants : tuple of str
        Plants it runs on (``"linear"``, ``"testbed"``; notebook 09 also
        ``"ieee39"``).
    figures : tuple of str
        Figures it writes to ``figures/`` (PNG and PDF; ``_<plant>`` appended
        on a plant other than the linear one).
    short : dict
        Parameters of a short run for the tests (papermill parameters).
    """

    name: str
    notebook: str
    title: str
    plants: tuple[str, ...]
    figures: tuple[str, ...]
    short: dict = field(default_factory=dict)

    def figure_files(self, plant: str) -> list[str]:
        """The PNG file names it writes on ``plant``."""
        suffix = "" if plant == "linear" else f"_{plant}"
        return [f"{f}{suffix}.png" for f in self.figures]


CHAPTERS = (
    Chapter("tutorial", "01_tutorial_cbf_lfc.ipynb",
            "The model, the safe set and the CBF-QP, step by step", ("linear",),
            ("tutorial_attack", "tutorial_barriers"), {"duration": 3.0}),
    Chapter("fig4", "02_fig4_rocof_attack.ipynb",
            "Fig. 4: a ROCOF-tripping attack, the SCC with α = 3 and 20", PLANTS,
            ("fig4_rocof_attack",),
            {"duration": 3.0, "edge_amplitudes": [0.2, 0.6, 0.2], "edge_durations": [3.0]}),
    Chapter("fig5", "03_fig5_bias_attack.ipynb",
            "Fig. 5: a bias on the frequency reference", PLANTS, ("fig5_bias_attack",),
            {"duration": 3.0}),
    Chapter("fig6", "04_fig6_load_step.ipynb", "Fig. 6: a legitimate load step", PLANTS,
            ("fig6_load_step",), {"duration": 3.0}),
    Chapter("fig7", "05_fig7_fault.ipynb",
            "Fig. 7: a fault at B5 and the over-current relay", ("testbed",),
            ("fig7_fault",), {"duration": 2.0}),
    Chapter("surface", "06_attack_surface.ipynb",
            "Which attacks does the SCC stop? Maps, readings and the α–T_s trade-off",
            ("linear",), ("readings", "attack_surface", "bias_surface", "alpha_ts_tradeoff"),
            {"amplitudes": [0.1, 0.5], "freqs": [0.5, 1.0], "biases": [0.02, 0.04],
             "tradeoff_alphas": [20.0], "tradeoff_Ts": [0.25], "load_steps": [0.1, 0.25],
             "readings_load_steps": [0.1], "duration": 10.0, "jobs": 1,
             "check_claims": False}),
    Chapter("kalman", "07_kalman.ipynb", "The SCC on a Kalman estimate", ("linear",),
            ("kalman_scc",), {"duration": 3.0}),
    Chapter("redteam", "08_red_team.ipynb",
            "Beyond the paper: a certified filter, made robust, and a red team", ("linear",),
            ("red_team", "certified_vs_paper", "robust_box", "load_during_attack"),
            {"families": ["square on P_c"], "family_maxiter": 2, "family_popsize": 3,
             "search_duration": 4.0, "n_seeds": 2, "freeform_attack_duration": 0.2,
             "freeform_duration": 2.0, "freeform_maxiter": 1, "map_amplitudes": [0.5, 1.0],
             "map_freqs": [0.3, 1.0], "plant_steps": [5e-4, 1e-3], "n_interior": 1,
             "n_box_attacks": 2, "box_duration": 5.0, "n_noise_seeds": 2, "noise_hours": 0.05,
             "margins": [0.1, 0.3], "load_steps": [0.1], "load_bounds": [0.1], "load_instants": 2,
             "testbed": False,
             "check_claims": False}),
    Chapter("multiarea", "09_multi_area.ipynb",
            "Beyond the paper: a filter at every area of an interconnected grid",
            ALL_PLANTS,
            ("multiarea_load_step", "multiarea_single", "multiarea_coordinated", "multiarea_ace"),
            {"duration": 10.0, "red_team_families": ["bias on ACE"], "red_team_maxiter": 1,
             "red_team_popsize": 2, "red_team_duration": 5.0}),
    Chapter("coupled", "10_coupled_certificate.ipynb",
            "Beyond the paper: certificates for a whole grid", ("linear",),
            ("coupled_certificate", "coupled_scaling"),
            {"duration": 10.0, "kundur_instants": [3.37], "scaling_areas": [2, 3],
             "scaling_ties": [2.0, 30.0], "restoration_grids": ["two-area"]}),
    Chapter("wire", "11_wire.ipynb",
            "Beyond the paper: the attack on a real industrial protocol (Modbus/TCP)",
            ("linear",), ("wire",),
            {"duration": 4.0, "realtime_duration": 2.0, "forensic_draws": 1}),
    Chapter("loads", "12_loads_and_sensors.ipynb",
            "Beyond the paper: loads and sensors as weapons", ("linear",),
            ("laa_gain_map", "laa_warning"),
            {"duration": 5.0, "families": ["step on load"], "maxiter": 1, "popsize": 2,
             "map_points": 9}),
)


def chapter(name: str) -> Chapter:
    """The chapter called ``name``; ``ValueError`` naming the known ones otherwise."""
    for c in CHAPTERS:
        if c.name == name:
            return c
    raise ValueError(f"unknown figure {name!r}; choose from {[c.name for c in CHAPTERS]}")
