"""Survey, not a timing: what the network between the control centre and the
substation does to a real-time run (docs/wire.md, "--delay").

Fig. 4's attack against the paper's filter (α = 20), 5 s of wall clock at the
10 ms control period, over Modbus/TCP and DNP3, with each network of ``NETWORKS``
(:class:`lfc.wire.Impairment`, made in the relay): the commands that missed their
tick (the generator held its last one), whether a relay tripped, the filter's
alarms, the median write round trip and the largest command the generator
received (0.5 pu: the attack arrived).  Wall-clock runs: the counts move a little
from run to run and with the machine's load.

Run: python bench/survey_wire_network.py [SECONDS]
"""

from __future__ import annotations

import sys

import pandas as pd

import lfc
from lfc.wire import Impairment, run_wire

NETWORKS = {"none": None, "2 ms": Impairment(delay=0.002),
            "4 ± 1 ms": Impairment(delay=0.004, jitter=0.001), "5 ms": Impairment(delay=0.005),
            "1 ms, 1 % loss": Impairment(delay=0.001, loss=0.01)}


def main(duration: float = 5.0) -> None:
    params = lfc.LFCParams()
    scc = lfc.SafetyFilter(params, lfc.RelaySettings(), alpha=20.0)
    rows = []
    for protocol in ("modbus", "dnp3"):
        for name, network in NETWORKS.items():
            run = run_wire(params, duration=duration, attack="fig4", scc=scc,
                           protocol=protocol, mode="realtime", impairment=network)
            ex = run.exchanges
            rows.append({"protocol": protocol, "one-way network": name,
                         "late commands": f"{int(ex.link.sum())} of {len(ex)}",
                         "tripped": run.tripped, "alarms": len(run.alarm_log),
                         "write median (ms)": round(float(ex.write_ms.median()), 1),
                         "largest command received (pu)":
                             round(float(ex.received.abs().max()), 3)})
    print(f"Fig. 4, paper's filter, {duration:g} s real time at 10 ms")
    print(pd.DataFrame(rows).to_string(index=False))


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 5.0)
