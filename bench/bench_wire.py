"""Benchmark: lockstep runs over the wire, in control periods per second.

Prints, from one run on this machine: the median wall time of a lockstep run over
Modbus/TCP and over DNP3 (Fig. 4's attack, the paper's filter at α = 20, 10 s at
a 10 ms control period: 1,000 exchanged commands, each a write and a read through
the man in the middle on loopback), the control periods per second against the
targets of the Field issue (>= 1,000 over Modbus/TCP, >= 300 over DNP3 on 2 cores),
and the ratio to the reference: the same scenario in :func:`lfc.simulate`, with
no sockets.

Run: python bench/bench_wire.py
"""

from __future__ import annotations

import statistics
import time

import lfc
from lfc.wire import run_wire

DURATION, PERIOD, REPEAT = 10.0, 0.01, 5
TARGET = {"modbus": 1000, "dnp3": 300}


def _median(call) -> float:
    times = []
    for _ in range(REPEAT):
        t0 = time.perf_counter()
        call()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    params, relays = lfc.LFCParams(), lfc.RelaySettings()
    scc = lfc.SafetyFilter(params, relays, alpha=20.0)
    periods = round(DURATION / PERIOD)
    attack = lfc.Sinusoid(0.5, 1.0, start=1.0)
    for protocol in TARGET:                         # connect once: imports, compilation
        run_wire(params, duration=0.1, attack="fig4", scc=scc, protocol=protocol)
    t_sim = _median(lambda: lfc.simulate(params, duration=DURATION, pc_attack=attack,
                                         scc=scc, relays=relays))
    print(f"lockstep over the wire: Fig. 4's attack, paper's filter, {DURATION:g} s at "
          f"{1e3 * PERIOD:g} ms ({periods} commands), median of {REPEAT}")
    print(f"reference, lfc.simulate of the same scenario: {1e3 * t_sim:.1f} ms "
          f"({periods / t_sim:,.0f} control periods/s)")
    for protocol, target in TARGET.items():
        t = _median(lambda: run_wire(params, duration=DURATION, attack="fig4", scc=scc,
                                     relays=relays, protocol=protocol))
        rate = periods / t
        print(f"{protocol:7s} {t:6.2f} s: {rate:,.0f} control periods/s (target >= {target}: "
              f"{'met' if rate >= target else 'NOT met'}), {t / t_sim:,.0f}x lfc.simulate")


if __name__ == "__main__":
    main()
