import os

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

# Property tests are derandomized by default, so the suite's verdict is reproducible
# (fixed seeds); HYPOTHESIS_PROFILE=explore draws new examples on every run.  A test's
# own count is tiers.examples(n): all n in the exhaustive tier.
settings.register_profile("default", deadline=None, max_examples=tiers.examples(200),
                          derandomize=True, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("explore", deadline=None, max_examples=tiers.examples(200),
                          suppress_health_check=[HealthCheck.too_slow])


def pytest_addoption(parser):
    parser.addoption("--exhaustive", action="store_true",
                     help="the exhaustive tier: every test and every scenario of every "
                          "battery (also LFC_TEST_TIER=exhaustive); tests/tiers.py")


def pytest_configure(config):
    """The tier (before any test module is imported, in every process: the workers
    inherit it), the markers, and — on pytest-xdist's controller, before its workers
    start — the engine's loops compiled in the background (``lfc.warmup``), once each
    and not once per worker, while the workers start and collect."""
    if config.getoption("exhaustive"):
        os.environ[tiers.TIER_ENV] = "exhaustive"
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


def pytest_sessionfinish(session):
    """A worker hands its counts to the controller (``workeroutput``)."""
    output = getattr(session.config, "workeroutput", None)
    if output is not None:
        output["lfc_left_tests"] = session.config.stash.get(_LEFT, 0)
        output["lfc_left_scenarios"] = sum(tiers.LEFT_OUT.values())


_WORKERS: dict[str, dict] = {}


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node, error):
    _WORKERS[node.gateway.id] = dict(getattr(node, "workeroutput", {}))


def pytest_unconfigure(config):
    """The last line of a default-tier run: what the exhaustive tier adds (after
    pytest's own summary); and no compilation left running."""
    _compiled(config)
    reporter = config.pluginmanager.get_plugin("terminalreporter")
    if tiers.exhaustive() or hasattr(config, "workerinput") or reporter is None:
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
