"""Settings shared by the whole suite."""

from __future__ import annotations

import gc
import os
from collections.abc import Iterator

import pytest
from hypothesis import HealthCheck, settings

# Timing on a shared machine is noisy: no per-example deadline. HYPOTHESIS_PROFILE=long
# runs many more examples (the fuzz soak), for use outside the normal suite.
settings.register_profile("default", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile(
    "long", deadline=None, max_examples=20_000, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))


@pytest.fixture
def without_collector_pauses() -> Iterator[None]:
    """No garbage collection during the test, none of earlier tests' garbage left.

    A full collection in a process that has run many tests pauses the event loop for
    milliseconds, longer than t1.5 at 19200 baud: on a paced virtual line, the receiver
    then sees a gap inside a frame. Tests that count such errors as failures use this.
    """
    gc.collect()
    gc.disable()
    try:
        yield
    finally:
        gc.enable()
