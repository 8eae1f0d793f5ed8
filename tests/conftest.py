import os

os.environ.setdefault("MPLBACKEND", "Agg")

import jax  # noqa: E402

# Tests run in float64 (DESIGN 4: never flip config at import in the library; tests choose).
jax.config.update("jax_enable_x64", True)
