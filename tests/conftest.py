import os

os.environ.setdefault("MPLBACKEND", "Agg")
# the CLI turns JAX's persistent compilation cache on; in-process CLI tests must not flip it
# for the rest of the suite
os.environ["JAXSQUEEZE_NO_CACHE"] = "1"


def _faster_compiles():
    """Compile the suite's programs with the options the library uses for its own top-level
    programs (jaxsqueeze.compiler: XLA:CPU's fusion emitters off, LLVM optimisation level 1):
    less XLA compile time, same run time and numbers (benchmarks/README.md, "Compilation and
    host work"); here as XLA flags, so the tests' own jits get them too. A flag is added only
    where this jaxlib knows it (an unknown XLA flag aborts the process), probed once in a child
    and passed on to pytest-xdist workers and notebook kernels through the environment."""
    import subprocess
    import sys
    flags = ["--xla_cpu_use_fusion_emitters=false", "--xla_backend_optimization_level=1"]
    if os.environ.get("JAXSQUEEZE_TEST_FLAGS_PROBED") or flags[0] in os.environ.get("XLA_FLAGS", ""):
        return
    os.environ["JAXSQUEEZE_TEST_FLAGS_PROBED"] = "1"
    for flag in flags:
        env = dict(os.environ, XLA_FLAGS=(os.environ.get("XLA_FLAGS", "") + " " + flag).strip(), JAX_PLATFORMS="cpu")
        probe = subprocess.run([sys.executable, "-c", "import jax; jax.numpy.zeros(1).block_until_ready()"], env=env,
                               capture_output=True)
        if probe.returncode == 0:
            os.environ["XLA_FLAGS"] = env["XLA_FLAGS"]


_faster_compiles()


def _shared_compile_cache():
    """One persistent compilation cache for the whole run: the xdist workers, and the CLI,
    notebook and batch processes the tests start, load a program another test compiled instead
    of compiling it again (a module's programs are freed when it ends). A fresh folder per run,
    made by the first process and passed on through the environment, set before JAX is
    imported and never changed (turning a used cache off or elsewhere is what aborted XLA).
    A size bound turns on JAX's file lock around every read and write of the folder (with the
    ``filelock`` package of the test extras): JAX writes an entry in place, and a worker reading
    it half-written would warn, which the tests that turn warnings into errors would fail on."""
    import importlib.util
    import tempfile
    if os.environ.get("JAX_COMPILATION_CACHE_DIR"):
        return None
    os.environ["JAX_COMPILATION_CACHE_DIR"] = tempfile.mkdtemp(prefix="jaxsqueeze-test-cache-")
    os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0.5"
    if importlib.util.find_spec("filelock") is not None:
        os.environ["JAX_COMPILATION_CACHE_MAX_SIZE"] = str(8 << 30)
    return os.environ["JAX_COMPILATION_CACHE_DIR"]


_MADE_CACHE = _shared_compile_cache()       # the folder, in the process that made it (removed at its end)
SHARED_CACHE = os.environ["JAX_COMPILATION_CACHE_DIR"]

import jax  # noqa: E402

# Tests run in float64 (DESIGN 4: never flip config at import in the library; tests choose).
jax.config.update("jax_enable_x64", True)

import pytest  # noqa: E402


def pytest_sessionfinish(session):
    if _MADE_CACHE and not hasattr(session.config, "workerinput"):
        import shutil
        shutil.rmtree(_MADE_CACHE, ignore_errors=True)


@pytest.fixture(autouse=True)
def _persistent_cache_stays_put():
    """No test may move or turn off the run's persistent compilation cache in this process: once
    used, JAX cannot change it reliably, and XLA aborted the whole suite writing a later program."""
    yield
    assert jax.config.jax_compilation_cache_dir == SHARED_CACHE, "a test moved the persistent compilation cache"


@pytest.fixture(autouse=True)
def _no_compile_left_running():
    """A compile started ahead (in a background thread) ends with its test: the next test's
    counts of traces and compiles are its own."""
    yield
    from jaxsqueeze import compiler
    compiler.wait_ahead()


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
