import os
import resource
import time
from pathlib import Path

# One BLAS thread in every process of the suite (pytest-xdist's workers, the notebook
# kernels and pools they start), set before anything loads numpy: the suite runs one
# worker per core, and OpenBLAS' default of a thread per core in each process left the
# cores oversubscribed, its idle threads spinning (``lfc.repro.runner.ONE_BLAS_THREAD``).
# A value set in the environment is kept.  Written here, not imported (importing lfc
# loads numpy); tests/test_notebooks.py checks the two agree.
BLAS_THREADS = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
for _name, _value in BLAS_THREADS.items():
    os.environ.setdefault(_name, _value)

import pytest  # noqa: E402
from hypothesis import HealthCheck, settings  # noqa: E402

import tiers  # noqa: E402



def pytest_addoption(parser):
    parser.addoption("--exhaustive", action="store_true",
                     help="the exhaustive tier: every test and every scenario of every "
                          "battery (also LFC_TEST_TIER=exhaustive); tests/tiers.py")


_STARTED = (time.monotonic(), 0.0)


def _cpu() -> float:
    """CPU seconds of this process and of the children it has waited for (the
    workers, and in turn their kernels and pools)."""
    own, children = (resource.getrusage(w) for w in (resource.RUSAGE_SELF,
                                                      resource.RUSAGE_CHILDREN))
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def pytest_configure(config):
    """The tier (before any test module is imported, in every process: the workers
    inherit it), the markers, and — on pytest-xdist's controller, before its workers
    start — the engine's loops compiled in the background (``lfc.warmup``), once each
    and not once per worker, while the workers start and collect."""
    global _STARTED
    _STARTED = (time.monotonic(), _cpu())
    if config.getoption("exhaustive"):
        os.environ[tiers.TIER_ENV] = "exhaustive"
    # Property tests are derandomized by default, so the suite's verdict is reproducible
    # (fixed seeds); HYPOTHESIS_PROFILE=explore draws new examples on every run.  A
    # test's own count is tiers.examples(n): all n in the exhaustive tier.
    settings.register_profile("default", deadline=None, max_examples=tiers.examples(200),
                              derandomize=True, suppress_health_check=[HealthCheck.too_slow])
    settings.register_profile("explore", deadline=None, max_examples=tiers.examples(200),
                              suppress_health_check=[HealthCheck.too_slow])
    settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))
    config.addinivalue_line("markers", "exhaustive: runs in the exhaustive tier only "
                                       "(tests/tiers.py)")
    config.addinivalue_line("markers", "andes_recorded: its grid runs on ANDES replay the "
                                       "committed recordings (lfc.testbed.stored_runs)")
    if not hasattr(config, "workerinput"):
        from lfc.warmup import start_compiling
        config.stash[_COMPILING] = start_compiling()


_COMPILING = pytest.StashKey()


def _compiled(config) -> None:
    """Wait for the loops compiled in the background (once)."""
    pending = config.stash.get(_COMPILING, None)
    if pending is not None:
        config.stash[_COMPILING] = None
        pending.result()
        config.stash[_DID_COMPILE] = pending.compiled


_DID_COMPILE = pytest.StashKey()
_PASSED = pytest.StashKey()


def pytest_collection_finish(session):
    """Without workers (``-n 0``): no test starts before the loops are compiled."""
    _compiled(session.config)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_node_collection_finished(node, ids):
    """With workers: no test is handed out before the loops are compiled."""
    _compiled(node.config)


def pytest_collection_modifyitems(config, items):
    """The exhaustive tier's own tests left out of the default tier; then the longest
    first (``@pytest.mark.long(seconds)``, their measured time with a warm cache), so
    no worker starts one near the end while the other idles; with
    ``--maxschedchunk 1`` pytest-xdist then hands the rest out one by one."""
    if not tiers.exhaustive():
        kept = [i for i in items if i.get_closest_marker("exhaustive") is None]
        left = [i for i in items if i.get_closest_marker("exhaustive") is not None]
        if left:
            config.hook.pytest_deselected(items=left)
            items[:] = kept
        config.stash[_LEFT] = len(left)

    def seconds(item) -> float:
        mark = item.get_closest_marker("long")
        return mark.args[0] if mark else 0.0
    items.sort(key=seconds, reverse=True)       # stable: the others keep their order


_LEFT = pytest.StashKey()


def pytest_sessionfinish(session, exitstatus):
    """A worker hands its counts to the controller (``workeroutput``); the controller
    notes whether the whole suite ran and passed (its time goes to the README)."""
    config = session.config
    suite = [Path(a).resolve() for a in config.args] == [Path(__file__).resolve().parent]
    config.stash[_PASSED] = (exitstatus == 0 and suite and not config.option.keyword
                             and not config.option.markexpr)
    output = getattr(session.config, "workeroutput", None)
    if output is not None:
        output["lfc_left_tests"] = session.config.stash.get(_LEFT, 0)
        output["lfc_left_scenarios"] = sum(tiers.LEFT_OUT.values())


_WORKERS: dict[str, dict] = {}


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node, error):
    _WORKERS[node.gateway.id] = dict(getattr(node, "workeroutput", {}))


def pytest_unconfigure(config):
    """The run's last lines (after pytest's own summary): its tier's wall and CPU time
    (also as JSON where ``$LFC_TIER_REPORT`` points: ``.ci/run`` checks the budget),
    and in the default tier what the exhaustive tier adds; no compilation left."""
    _compiled(config)
    reporter = config.pluginmanager.get_plugin("terminalreporter")
    if hasattr(config, "workerinput") or reporter is None:
        return
    tier = "exhaustive" if tiers.exhaustive() else "default"
    wall, cpu = time.monotonic() - _STARTED[0], _cpu() - _STARTED[1]
    reporter.write_line(f"the {tier} tier took {wall:.0f} s wall, {cpu:.0f} s of CPU "
                        f"(this process and the workers, kernels and pools it started)")
    if os.environ.get("LFC_TIER_REPORT"):
        import json
        Path(os.environ["LFC_TIER_REPORT"]).write_text(json.dumps(
            {"tier": tier, "wall": round(wall, 1), "cpu": round(cpu, 1)}))
    if config.stash.get(_PASSED, False):          # the whole tier passed: the README's time
        from lfc.repro import runner
        compiled = config.stash.get(_DID_COMPILE, False)
        runner.record_time(runner.ROOT / "build", "python -m pytest" + (
            " --exhaustive" if tiers.exhaustive() else "") + ("" if compiled else ", again"),
            wall, cpu,
            "the loops compiled in the run" if compiled else "the loops in numba's cache")
    if tiers.exhaustive():
        return
    if _WORKERS:   # every worker collected the same tests; battery scenarios add up
        tests = max(w.get("lfc_left_tests", 0) for w in _WORKERS.values())
        scenarios = sum(w.get("lfc_left_scenarios", 0) for w in _WORKERS.values())
    else:
        tests, scenarios = config.stash.get(_LEFT, 0), sum(tiers.LEFT_OUT.values())
    line = tiers.summary(tests, scenarios)
    if line:
        reporter.write_line(line)


@pytest.fixture(autouse=True)
def _andes_recordings(request, monkeypatch):
    """Only a test marked ``andes_recorded`` reads the committed ANDES recordings, and
    only such a test writes them (``LFC_ANDES_RECORD=write python -m pytest -m
    andes_recorded``: docs/testbed.md): every other test runs what it asks ANDES for."""
    if request.node.get_closest_marker("andes_recorded") is None:
        monkeypatch.setenv("LFC_ANDES_RECORDINGS", "off")
        monkeypatch.delenv("LFC_ANDES_RECORD", raising=False)
