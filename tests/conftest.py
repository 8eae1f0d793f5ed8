import os

os.environ.setdefault("MPLBACKEND", "Agg")
# the CLI turns JAX's persistent compilation cache on; in-process CLI tests must not flip it
# for the rest of the suite
os.environ["JAXSQUEEZE_NO_CACHE"] = "1"

import jax  # noqa: E402

# Tests run in float64 (DESIGN 4: never flip config at import in the library; tests choose).
jax.config.update("jax_enable_x64", True)
