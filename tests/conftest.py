"""Settings for the whole suite."""

import os

from hypothesis import settings

# `.ci/run` draws the same examples on every run, so that CI goes red only when a change breaks
# something. Anywhere else the property tests (the fuzzers in tests/reliability) draw afresh each
# run and keep looking for damage the code does not handle yet.
settings.register_profile("ci", derandomize=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))
