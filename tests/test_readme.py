"""The README's Python examples run exactly as written (one namespace, in a scratch folder)."""
import os
import re
import warnings

import jax
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def python_blocks():
    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as f:
        return re.findall(r"```python\n(.*?)```", f.read(), flags=re.S)


def test_readme_examples_run(tmp_path, monkeypatch):
    blocks = python_blocks()
    assert len(blocks) >= 2
    monkeypatch.chdir(tmp_path)
    ns = {}
    # README, "Your JAX settings": the examples run as written with rank promotion raised and
    # strict dtype promotion
    with warnings.catch_warnings(record=True) as caught, jax.numpy_rank_promotion("raise"), \
            jax.numpy_dtype_promotion("strict"):
        warnings.simplefilter("always")
        for block in blocks:
            exec(compile(block, "README.md", "exec"), ns)          # noqa: S102  (our own README)
    import jaxsqueeze as jsq
    # "Above they do: this mesh has 5.9 mm edges away from the grip, 17° for the 10 mm fingertips
    # against μ = 0.2's 11.3°" (grasp_map and optimize_placement, each once)
    said = [str(w.message) for w in caught if w.category is jsq.plan.PlacementResolutionWarning]
    assert len(said) == 2 and all(t.startswith("boundary edges 0.00588 m long under fingertips of radius 0.01 m")
                                  and "17.1 deg off its normal, beyond the friction cone's 11.3 deg" in t for t in said), said
    assert ns["res"].outcome == jsq.Status.SUCCESS
    assert os.path.exists(tmp_path / "out" / "deformed.png")
    assert np.all(np.isfinite(np.asarray(ns["dwork"])))
    assert ns["best"].quality > 0 and ns["gmap"].feasible().any()
    assert float(jsq.quality.adversary_work(ns["pushed"])) > 0


def test_the_flat_module_names_of_version_0_1_import_as_aliases():
    """README: ``jaxsqueeze.fem``, ``jaxsqueeze.scene``, ``jaxsqueeze.views``, … still import
    (``import``, ``from … import``, attribute access), each as the very module of its new home."""
    import importlib

    import jaxsqueeze as jsq
    for old, home in jsq.MODULES.items():
        new = importlib.import_module(f"jaxsqueeze.{home}")
        assert importlib.import_module(f"jaxsqueeze.{old}") is new, old
        assert getattr(jsq, old) is new
    import jaxsqueeze.fem
    from jaxsqueeze.views import summary
    assert jaxsqueeze.fem.stiffness is jsq.mechanics.fem.stiffness and summary is jsq.post.views.summary
    # a name that never existed is still an ImportError
    import pytest
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("jaxsqueeze.nosuchmodule")
