"""The suite's two tiers: the default one (``python -m pytest``) and the exhaustive one
(``python -m pytest --exhaustive``, or ``LFC_TEST_TIER=exhaustive`` in the environment).

Both tiers run the same test ids.  Three things differ:

* a test marked ``@pytest.mark.exhaustive`` runs only in the exhaustive tier (a
  notebook executed, ANDES run live for minutes, a fit computed again);
* a battery (:class:`Battery`: one test over many scenarios) runs all of its
  scenarios in the exhaustive tier and, in the default tier, the ``k`` most severe
  ones recorded in ``tests/data/worst_cases.json`` (severity: the largest peak of
  frequency or ROCOF over its relay setting, ≥ 1 trips; the least room left).  The
  exhaustive tier checks the record: a battery whose ``k`` most severe scenarios are
  no longer the recorded ones fails, saying so (``LFC_UPDATE_WORST_CASES=1`` writes
  the new ones);
* a red-team search (:func:`searched`) runs in the exhaustive tier; the default tier
  takes the attack it found from the record;
* hypothesis draws :func:`examples` examples: a test's full count in the exhaustive
  tier, a quarter of it (at least 5) in the default one.

A battery's constructed worst case (a load step of exactly the bound 1 ms after a
control sample, the attack the proof is about) is a scenario like the others: its
severity puts it in the record.  At the end of a run, one line says how many tests and
battery scenarios the exhaustive tier adds (:func:`summary`).
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Generic, TypeVar

#: the environment variable that selects the tier (``exhaustive``; unset: default)
TIER_ENV = "LFC_TEST_TIER"
#: the environment variable that lets the exhaustive tier rewrite the record
UPDATE_ENV = "LFC_UPDATE_WORST_CASES"
RECORD = Path(__file__).parent / "data" / "worst_cases.json"
#: relative: two severities closer than this are the same (a BLAS kernel or another
#: machine moves the last bits; tests/regression_set.py's cross-machine tolerance)
SAME = 1e-6
#: scenarios each tier left out, this process (the conftest reports them)
LEFT_OUT: dict[str, int] = {}

T = TypeVar("T")


def exhaustive() -> bool:
    """Whether this run is the exhaustive tier."""
    value = os.environ.get(TIER_ENV, "").strip().lower()
    if value not in ("", "default", "exhaustive"):
        raise ValueError(f"{TIER_ENV} must be 'default' or 'exhaustive' (or unset), "
                         f"got {os.environ[TIER_ENV]!r}")
    return value == "exhaustive"


def examples(n: int) -> int:
    """Hypothesis' ``max_examples`` for a test that draws ``n`` in the exhaustive tier."""
    return n if exhaustive() else max(5, n // 4)


def _read() -> dict:
    return json.loads(RECORD.read_text()) if RECORD.exists() else {}


class Battery(Generic[T]):
    """One battery test's scenarios in this tier.

    Parameters
    ----------
    key : str
        The battery's name in the record (the test's, with its parameters).
    scenarios : sequence
        Every scenario of the battery (what the exhaustive tier runs).
    label : callable
        A scenario's name: unique in the battery and stable from run to run (it names
        the scenario in the record).
    k : int
        How many of the most severe the default tier runs.

    Attributes
    ----------
    scenarios : list
        The scenarios to run in this tier (the record's, in the battery's order, in the
        default tier).
    """

    def __init__(self, key: str, scenarios: Sequence[T], label: Callable[[T], str],
                 k: int = 3) -> None:
        self.key, self.k, self.all = key, k, list(scenarios)
        self.labels = [label(s) for s in self.all]
        if len(set(self.labels)) != len(self.labels):
            raise ValueError(f"{key}: two scenarios share a label")
        if exhaustive():
            self.scenarios = self.all
            return
        recorded = _read().get(key)
        if recorded is None:
            raise AssertionError(f"{key}: no worst cases recorded in {RECORD.name}; run "
                                 f"{UPDATE_ENV}=1 python -m pytest --exhaustive -k ... once")
        names = [case["label"] for case in recorded["cases"]]
        missing = set(names) - set(self.labels)
        if missing:
            raise AssertionError(f"{key}: recorded worst cases {sorted(missing)} are not in "
                                 f"the battery any more; record them again ({UPDATE_ENV}=1 "
                                 f"python -m pytest --exhaustive)")
        self.scenarios = [s for s, name in zip(self.all, self.labels) if name in names]
        LEFT_OUT[key] = len(self.all) - len(self.scenarios)

    @classmethod
    def of_table(cls, key: str, table, k: int = 3) -> "Battery":
        """A battery of a scenario table's rows (a ``simulate_many`` table): each row
        named by its values; :attr:`scenarios` are index labels (``table.loc[...]``)."""
        def short(v) -> str:
            if isinstance(v, (tuple, list)) or getattr(v, "ndim", 0) > 0:   # sampled
                return "#" + hashlib.sha1(repr(tuple(map(float, v))).encode()).hexdigest()[:12]
            return repr(v.item() if hasattr(v, "item") else v)

        def label(i) -> str:
            return ", ".join(f"{c}={short(v)}" for c, v in table.loc[i].items()
                             if not (isinstance(v, float) and v != v))
        return cls(key, list(table.index), label, k)

    def record(self, severity: Iterable[float], flagged: Iterable[float] | None = None
               ) -> None:
        """Check (exhaustive tier) that the recorded scenarios are the ``k`` most severe
        of ``severity`` (one per scenario run, in :attr:`scenarios`' order) and, given
        ``flagged`` (per scenario: the samples flagged ``outside``, or whatever count a
        finding is about), the ``k`` where it is largest (and above 0); with
        ``LFC_UPDATE_WORST_CASES=1`` write them instead.  Nothing in the default tier."""
        if not exhaustive():
            return
        values = [float(v) for v in severity]
        flags = [float(v) for v in flagged] if flagged is not None else [0.0] * len(values)
        if not len(values) == len(flags) == len(self.all):
            raise ValueError(f"{self.key}: {len(values)} severities for {len(self.all)} "
                             f"scenarios")
        worst = sorted(range(len(values)), key=lambda i: (-values[i], self.labels[i]))
        flagged = [i for i in sorted(range(len(flags)), key=lambda i: (-flags[i], self.labels[i]))
                   if flags[i] > 0]
        top = [{"label": self.labels[i], "severity": round(values[i], 9),
                "by": "severity" if i in worst[:self.k] else "flagged",
                **({"flagged": int(flags[i])} if flags[i] else {})}
               for i in dict.fromkeys(worst[:self.k] + flagged[:self.k])]
        if os.environ.get(UPDATE_ENV) == "1":
            _write(self.key, {"k": self.k, "of": len(values), "cases": top})
            return
        recorded = _read().get(self.key)
        assert recorded is not None, f"{self.key}: not recorded ({UPDATE_ENV}=1 writes it)"
        index = {name: i for i, name in enumerate(self.labels)}
        names = [case["label"] for case in recorded["cases"]]
        stale = [name for name in names if name not in index]
        kth = values[worst[min(self.k, len(values)) - 1]]
        by_severity = [name for name, case in zip(names, recorded["cases"])
                       if case.get("by", "severity") == "severity" and name in index]
        dropped = [name for name in by_severity
                   if values[index[name]] < kth - SAME * max(1.0, abs(kth))]
        kth_flag = flags[flagged[min(self.k, len(flagged)) - 1]] if flagged else 0.0
        unflagged = [self.labels[i] for i in flagged[:self.k]
                     if self.labels[i] not in names and flags[i] > kth_flag]
        assert not (stale or dropped or unflagged) and recorded["of"] == len(values) and \
            len(by_severity) == min(self.k, len(values)), (
                f"{self.key}: the battery's worst scenarios are now {top}; the record holds "
                f"{recorded['cases']} of {recorded['of']}: rerun with {UPDATE_ENV}=1 to "
                f"write them to {RECORD}")


def searched(key: str, search: Callable[[], dict]) -> dict:
    """A red-team search's result (a dict with a ``severity``): in the default tier the
    one recorded in ``tests/data/worst_cases.json``; in the exhaustive tier the search
    runs, and fails if it found an attack more severe than the recorded one (by more
    than ``SAME``: the record no longer holds the worst case; ``LFC_UPDATE_WORST_CASES=1``
    writes it).  Lists read back as tuples."""
    recorded = _read().get(key)
    if not exhaustive():
        if recorded is None:
            raise AssertionError(f"{key}: no search recorded in {RECORD.name}; run "
                                 f"{UPDATE_ENV}=1 python -m pytest --exhaustive -k ... once")
        LEFT_OUT[key] = 1
        return {k: tuple(v) if isinstance(v, list) else v for k, v in recorded["found"].items()}
    found = search()
    if os.environ.get(UPDATE_ENV) == "1":
        _write(key, {"found": json.loads(json.dumps(found))})
        return found
    assert recorded is not None, f"{key}: not recorded ({UPDATE_ENV}=1 writes it)"
    worst = recorded["found"]["severity"]
    assert found["severity"] <= worst + SAME * max(1.0, abs(worst)), (
        f"{key}: the search found severity {found['severity']:.9g}, above the recorded "
        f"{worst:.9g}: rerun with {UPDATE_ENV}=1 to record {found}")
    return found


def recorded(key: str) -> dict:
    """The search result recorded under ``key`` in ``tests/data/worst_cases.json`` (any
    tier: what a page quotes is checked against it)."""
    entry = _read().get(key)
    if entry is None:
        raise AssertionError(f"{key}: no search recorded in {RECORD.name}; run "
                             f"{UPDATE_ENV}=1 python -m pytest --exhaustive -k ... once")
    return entry["found"]


def _write(key: str, entry: dict) -> None:
    """Replace one battery's entry of the record (under a lock: workers write at once)."""
    from lfc._files import folder_lock, write_atomic
    with folder_lock(Path(tempfile.gettempdir()) / "lfc-worst-cases"):
        record = _read()
        record[key] = entry
        write_atomic(RECORD, json.dumps(dict(sorted(record.items())), indent=1,
                                        ensure_ascii=False) + "\n")


def severity(max_abs_dw: float, max_abs_rocof: float, F: float, rocof_limit: float) -> float:
    """A run's largest peak over its relay setting (≥ 1 trips): frequency or ROCOF."""
    return max(max_abs_dw / F, max_abs_rocof / rocof_limit)


def summary(tests: int, scenarios: int) -> str:
    """The run's last line in the default tier."""
    if not (tests or scenarios):
        return ""
    return (f"the exhaustive tier adds {tests} tests and {scenarios} battery scenarios "
            f"(every seed, plant and instant; notebooks, ANDES live, fits): "
            f"python -m pytest --exhaustive")
