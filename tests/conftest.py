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


@pytest.fixture(autouse=True, scope="module")
def _free_compiled_programs():
    """Drop this module's compiled programs when it ends. Every XLA:CPU executable holds its own
    memory mappings; a whole suite in one process passed Linux's limit of 65,530 mappings per
    process (vm.max_map_count), and the next compile aborted the process."""
    yield
    jax.clear_caches()
    path = os.environ.get("JAXSQUEEZE_MAPS_LOG")
    if path:                                    # diagnosis: mappings left after each module
        with open(path, "a") as f, open("/proc/self/maps") as maps:
            f.write(f"{sum(1 for _ in maps)}\n")
