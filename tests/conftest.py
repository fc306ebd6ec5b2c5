import os

from hypothesis import HealthCheck, settings

# Property tests are derandomized by default, so the suite's verdict is reproducible
# (fixed seeds); HYPOTHESIS_PROFILE=explore draws new examples on every run.
settings.register_profile("default", deadline=None, max_examples=200, derandomize=True,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("explore", deadline=None, max_examples=200,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))
