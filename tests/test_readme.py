"""The README's Python examples run exactly as written (one namespace, in a scratch folder)."""
import os
import re

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
    for block in blocks:
        exec(compile(block, "README.md", "exec"), ns)          # noqa: S102  (our own README)
    import jaxsqueeze as jsq
    assert ns["res"].outcome == jsq.Status.SUCCESS
    assert os.path.exists(tmp_path / "out" / "deformed.png")
    assert np.all(np.isfinite(np.asarray(ns["dwork"])))
    assert ns["best"].quality > 0 and ns["gmap"].feasible().any()
    assert float(jsq.quality.adversary_work(ns["pushed"])) > 0
