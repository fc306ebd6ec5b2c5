"""Where a claim of the paper does not hold on a plant, recognized from the run:
the documented deviations (``DEVIATIONS``), each a predicate on this run's
metrics and an explanation with its numbers.

``python -m lfc reproduce`` shows a failed claim that matches one as "no
(documented)"; :func:`lfc.repro.notebook.record_claims` fails a notebook whose
claim fails another way, or whose documented deviation no longer occurs.
``docs/testbed.md`` explains them ("Where the testbed differs").  The multi-area records
(:func:`multiarea_records`) are built here, so the names the predicates read
are defined where they are read.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from lfc._format import count, number
from lfc.result import Result

__all__ = ["DEVIATIONS", "Deviation", "multiarea_records"]


@dataclass(frozen=True)
class Deviation:
    """A claim of the paper that does not hold on a plant, recognized from the run.

    ``matches(metrics)`` says whether the run failed the claim in the documented
    way (which relay, within what range); ``explain(metrics)`` says why, with the
    run's numbers.  ``metrics`` maps each run of the notebook to its
    :meth:`Result.metrics` (as in ``metrics.json``).  A failure that does not
    match, or a documented deviation that no longer occurs, fails the notebook.
    """

    plant: str
    claim: str
    matches: Callable[[dict], bool]
    explain: Callable[[dict], str]


def _fig5_testbed_matches(m: dict) -> bool:
    """OF2 (not another relay) trips with the SCC, the frequency within 0.01 pu of OF2."""
    return m["scc"]["first_trip_relay"] == "OF2" and 0.03 < m["scc"]["max_abs_dw_meas"] <= 0.04


def _fig5_testbed_explain(m: dict) -> str:
    s = m["scc"]
    return (f"the fitted design model under-predicts the testbed's frequency near the edge of "
            f"its safe set, so the SCC's prediction leaves the set only after the frequency "
            f"has, and outside it the default reading ('hold') only stops the prediction from "
            f"getting worse: the frequency reaches {1 + s['max_abs_dw_meas']:.4f} pu and OF2 "
            f"trips at {s['first_trip_t']:.2f} s (without SCC at "
            f"{m['no_scc']['first_trip_t']:.2f} s)")


def _certified_areas(m: dict, attack: str, plant: str = "") -> dict[str, dict]:
    """Notebook 09's metrics of ``attack`` under the certified filters, by area:
    on the notebook's plant, or with ``plant="model/"`` on the design model."""
    prefix = f"{plant}{attack}/certified/"
    return {k.rsplit("/", 1)[1]: v for k, v in m.items() if k.startswith(prefix)}


def _held_not_tripped(attack: str) -> Callable[[dict], bool]:
    """Notebook 09 on ANDES: the certified filters flagged ``outside`` under
    ``attack`` and no area tripped."""
    def matches(m: dict) -> bool:
        runs = _certified_areas(m, attack).values()
        return bool(runs) and sum(r["outside"] for r in runs) > 0 and not any(
            r["tripped"] for r in runs)
    return matches


def _held_explain(attack: str) -> Callable[[dict], str]:
    """Why, from the run: the ``outside`` counts on ANDES and on the design model
    itself, and assumption (c) (the net disturbance's largest move in a control
    period against ``load_bound``)."""
    def explain(m: dict) -> str:
        andes, model = _certified_areas(m, attack), _certified_areas(m, attack, "model/")

        def counts(runs: dict) -> str:
            return ", ".join(f"{k} {count(v['outside'])}" for k, v in runs.items())

        if any(v["outside"] for v in model.values()):
            cause = ("the tie-line flow drifts while a command is held, which ends the "
                     "guarantee on the fitted model itself too; ANDES not being that model "
                     "(assumption (a)) adds the rest")
        else:
            cause = ("ANDES is not the fitted design model (assumption (a)): on the model "
                     "itself no filter flags outside")
        moves = ", ".join(f"{k} {number(v['disturbance_step'])} pu against "
                          f"{number(v['load_bound'])}"
                          for k, v in andes.items())
        held = all(v["disturbance_step"] <= v["load_bound"] for v in andes.values())
        return (f"at some control samples no command was certified and the held one failed its "
                f"re-check (control samples flagged outside on ANDES: {counts(andes)}; on the "
                f"fitted design model itself, the linear engine with the exact state: "
                f"{counts(model)}): {cause}. The net disturbance's largest move within a "
                f"control period on ANDES: {moves} (assumption (c) "
                f"{'held' if held else 'failed too'}). The filters held their command and no "
                f"area tripped")
    return explain


# Shown by ``python -m lfc reproduce`` as "no (documented)" and explained in
# docs/testbed.md ("Where the testbed differs").
DEVIATIONS = (
    Deviation("testbed", "with SCC no relay trips", _fig5_testbed_matches, _fig5_testbed_explain),
    Deviation("testbed", "with SCC frequency stays below OF2", _fig5_testbed_matches,
              _fig5_testbed_explain),
    *(Deviation("testbed", f"{attack} attack: no certified filter flags outside",
                _held_not_tripped(attack), _held_explain(attack))
      for attack in ("single", "coordinated", "ACE")),
)


def multiarea_records(load_runs: dict, attack_runs: dict[str, dict], model_runs: dict,
                      load_bounds: dict[int, float]) -> tuple[dict[str, Result], dict]:
    """Notebook 09's runs, one record per area, for ``metrics.json`` and the deviations.

    Parameters
    ----------
    load_runs : dict of str to Result
        Load steps, by filter setting.
    attack_runs : dict of str to dict of str to Result
        Attack name -> filter setting -> run (on the notebook's plant).
    model_runs : dict of str to Result
        Attack name -> the certified filters' run on the fitted design model itself.
    load_bounds : dict of int to float
        Each area's certified filter's ``load_bound`` (pu).

    Returns
    -------
    areas : dict of str to Result
        ``"<load|attack>/<setting>/area<i>"`` (and ``"model/<attack>/certified/area<i>"``)
        -> that area's result.
    extra : dict of str to dict
        The same names -> ``outside`` (control samples flagged), ``disturbance_step``
        (the net disturbance's largest move in a control period, pu) and ``load_bound`` (pu).
    """
    runs = ({f"load/{k}": r for k, r in load_runs.items()}
            | {f"{n}/{k}": r for n, by_kind in attack_runs.items() for k, r in by_kind.items()}
            | {f"model/{n}/certified": r for n, r in model_runs.items()})
    areas = {f"{name}/area{a}": area for name, r in runs.items() for a, area in enumerate(r.areas)}
    extra = {f"{name}/area{a}": {"outside": int(area.alarms.outside.sum()),
                                 "disturbance_step": r.disturbance_step(a),
                                 "load_bound": load_bounds[a]}
             for name, r in runs.items() for a, area in enumerate(r.areas)}
    return areas, extra
