import os

# One BLAS thread in every process of the suite (pytest-xdist's workers, the notebook
# kernels and pools they start), set before anything loads numpy: the suite runs one
# worker per core, and OpenBLAS' default of a thread per core in each process left the
# cores oversubscribed, its idle threads spinning (``lfc.repro.runner.ONE_BLAS_THREAD``:
# half the CPU time).  A value set in the environment is kept.  Written here, not
# imported (importing lfc loads numpy); tests/test_notebooks.py checks the two agree.
BLAS_THREADS = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
for _name, _value in BLAS_THREADS.items():
    os.environ.setdefault(_name, _value)

from hypothesis import HealthCheck, settings

# Property tests are derandomized by default, so the suite's verdict is reproducible
# (fixed seeds); HYPOTHESIS_PROFILE=explore draws new examples on every run.
settings.register_profile("default", deadline=None, max_examples=200, derandomize=True,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("explore", deadline=None, max_examples=200,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))


def pytest_configure(config):
    """Before any test (on pytest-xdist's controller, before its workers start):
    the engine's loops compiled once each, in parallel (``lfc.warmup``), not once
    per worker and per subprocess that finds the cache cold."""
    if not hasattr(config, "workerinput"):
        from lfc.warmup import compile_kernels
        compile_kernels()


def pytest_collection_modifyitems(config, items):
    """The longest tests first (``@pytest.mark.long(seconds)``, their measured time
    with a warm cache), so no worker starts one near the end while the other idles;
    with ``--maxschedchunk 1`` pytest-xdist then hands the rest out one by one."""
    def seconds(item) -> float:
        mark = item.get_closest_marker("long")
        return mark.args[0] if mark else 0.0
    items.sort(key=seconds, reverse=True)       # stable: the others keep their order
