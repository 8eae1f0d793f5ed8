import os

os.environ.setdefault("MPLBACKEND", "Agg")
# the CLI turns JAX's persistent compilation cache on; in-process CLI tests must not flip it
# for the rest of the suite
os.environ["JAXSQUEEZE_NO_CACHE"] = "1"

import jax  # noqa: E402

# Tests run in float64 (DESIGN 4: never flip config at import in the library; tests choose).
jax.config.update("jax_enable_x64", True)

import pytest  # noqa: E402


@pytest.fixture(autouse=True)
def _persistent_cache_stays_off():
    """No test may turn JAX's persistent compilation cache on in this process: once used, JAX
    cannot turn it off reliably, and XLA aborted the whole suite writing a later program."""
    yield
    assert not jax.config.jax_compilation_cache_dir, "a test turned the persistent compilation cache on"
