"""Safety filters: the paper's SCC and the certified filter, behind one interface.

``SafetyFilter(params, relays, method=..., **options)`` builds the method
registered under that name (``METHODS``; each method is a module here, with its
options documented on its backend class) and calls it through the compiled
dispatcher, one state at a time (:meth:`SafetyFilter.filter`) or many
(:meth:`SafetyFilter.filter_batch`).  A filter never raises for numeric
trouble and always returns a finite command; ``FilterInfo`` says what it did.
"""

from __future__ import annotations

import numpy as np

from lfc.filters.base import (ALARM_BITS, ALARM_FLAGS, MEMORY, Backend, FilterInfo,
                              binding_names, flag)
from lfc.filters.certified import CertifiedFilter
from lfc.filters.dispatch import PYTHON, decide, decide_many, register_python
from lfc.filters.paper import (CONFLICT_RULES, DEFAULT_READING, OUTSIDE_RULES, PREDICTIONS,
                               PaperFilter)
from lfc.model import STATES, LFCParams
from lfc.relays import RelaySettings

__all__ = ["ALARM_BITS", "ALARM_FLAGS", "CONFLICT_RULES", "DEFAULT_READING", "METHODS",
           "OUTSIDE_RULES", "PREDICTIONS", "FilterInfo", "SafetyFilter", "alarm_mask",
           "binding_names"]

REGISTRY: dict[str, type[Backend]] = {"paper": PaperFilter, "certified": CertifiedFilter}
METHODS = tuple(REGISTRY)


def alarm_mask(flags: dict[str, np.ndarray]) -> np.ndarray:
    """:attr:`FilterInfo.alarm` for the flags of :meth:`SafetyFilter.filter_batch`."""
    return np.logical_or.reduce([flags[f] for f in ALARM_FLAGS if f in flags])


class SafetyFilter:
    """A safety filter at the generator: minimally modify the governor command so
    that the frequency and ROCOF relays stay safe.

    Parameters
    ----------
    params : LFCParams
        Design model.
    relays : RelaySettings, optional
        Relay settings defining the safe set (default IEEE 1547 Cat. III).
    method : str
        ``"paper"`` (default): the paper's CBF-QP, :class:`lfc.filters.paper.PaperFilter`
        (options ``alpha``, ``Ts``, ``solver``, ``u_min``, ``u_max``,
        ``slack_weight``, ``outside_rule``, ``conflict``, ``prediction``);
        ``"certified"``: the filter with a guarantee,
        :class:`lfc.filters.certified.CertifiedFilter` (options ``period``,
        ``horizon``, ``load_bound``, ``margin``, ``u_min``, ``u_max``).
    **options
        The method's options.

    Raises
    ------
    ValueError
        For an unknown method, an option the method does not take, or an
        invalid option value (the message names it).
    """

    def __init__(self, params: LFCParams, relays: RelaySettings | None = None, *,
                 method: str = "paper", **options) -> None:
        if method not in REGISTRY:
            raise ValueError(f"method must be one of {METHODS}, got {method!r}")
        self.params = params
        self.relays = relays if relays is not None else RelaySettings()
        try:
            self.backend = REGISTRY[method](params, self.relays, **options)
        except TypeError as err:
            raise ValueError(f"method {method!r} takes no such option: {err}") from None
        self.method = method
        if self.backend.jit:
            self.method_id, self.data = self.backend.method_id, self.backend.data
        else:   # called back from compiled code
            self.method_id, self.data = PYTHON, register_python(self.backend)
        self.reset()

    def __getattr__(self, name: str):
        """The backend's options (``alpha``, ``Ts``, ``cert``, ...) read through."""
        if name == "backend":
            raise AttributeError(name)
        return getattr(self.backend, name)

    def __repr__(self) -> str:
        return self.backend.describe()

    def reset(self) -> None:
        """Forget the memory of earlier calls (held or last applied command)."""
        self._memory = np.zeros(MEMORY)
        self._batch_memory = np.zeros((0, MEMORY))

    def filter(self, x: np.ndarray, u_ref: float, p_load: float = 0.0
               ) -> tuple[float, FilterInfo]:
        """Filter one governor command.

        Parameters
        ----------
        x : array_like, shape (5,)
            State ``[dPg, dPm, dw, dw_meas, rocof_meas]`` (pu, pu/s): true or estimated.
        u_ref : float
            Incoming governor command dPc (pu).
        p_load : float
            Load change the filter assumes (pu); 0 when unmeasured (E7).

        Returns
        -------
        u : float
            Command to apply (pu), always finite.
        info : FilterInfo
            What the filter did and why.

        Raises
        ------
        ValueError
            If ``x`` does not have 5 entries (a programming error, not numeric trouble).
        """
        x = np.asarray(x, float).ravel()
        if x.shape != (5,):
            raise ValueError(f"x must have 5 entries {STATES}, got {x.size}")
        u_ref = float(u_ref)
        out = decide(self.method_id, self.data, x, u_ref, float(p_load), self._memory)
        return out[0], self.backend.info(u_ref, out)

    def filter_batch(self, x: np.ndarray, u_ref: np.ndarray, p_load: np.ndarray | None = None
                     ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Filter N commands at once (each row has its own memory, kept between
        calls while N stays the same).

        Parameters
        ----------
        x : ndarray, shape (N, 5)
            States (pu, pu/s).
        u_ref : ndarray, shape (N,)
            Incoming commands (pu).
        p_load : ndarray, shape (N,), optional
            Load change the filter assumes (pu); default 0 (unmeasured, E7).

        Returns
        -------
        u : ndarray, shape (N,)
            Applied commands (pu), always finite.
        flags : dict of ndarray
            ``active``, ``infeasible``, ``outside``, ``invalid_input``,
            ``solver_error`` (N,), ``h``, ``margin``, ``y`` (N, 2) as in
            :class:`FilterInfo`, and the method's ``details`` (N, 2 each).
        """
        x = np.ascontiguousarray(np.asarray(x, float).reshape(-1, 5))
        u_ref = np.asarray(u_ref, float).reshape(-1)
        p = np.zeros(len(u_ref)) if p_load is None else np.asarray(p_load, float).reshape(-1)
        if len(self._batch_memory) != len(u_ref):
            self._batch_memory = np.zeros((len(u_ref), MEMORY))
        bits, values = np.zeros(len(u_ref), np.int64), np.zeros((len(u_ref), 8))
        u = decide_many(self.method_id, self.data, x, u_ref, p, self._batch_memory, bits, values)
        out = {name: flag(bits, name) for name in ALARM_FLAGS}
        out.update(h=values[:, 0:2], margin=values[:, 2:4], y=values[:, 4:6], bits=bits)
        d = self.backend.details(values[:, 6], values[:, 7], bits)
        out.update({k: np.column_stack(v) for k, v in d.items()})
        return u, out

