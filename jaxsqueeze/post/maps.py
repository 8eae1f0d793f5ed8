"""Pictures of grasp planning: the grasp map as a heat map over (s_0, s_1), with infeasible
pairs masked, the best grasps marked and a search's paths drawn on it."""
from __future__ import annotations

import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure

MM = 1e3


def plot_grasp_map(gmap, search=None, label: str = "quality", ax=None) -> Figure:
    """Heat map of ``gmap.quality`` over finger positions (s_0, s_1) [mm along the boundary].

    Pairs whose squeeze did not succeed are grey (infeasible grip: light; failed squeeze:
    dark); the best feasible grasps are marked with stars (the best in white); a
    :class:`~jaxsqueeze.plan.Search` adds one path per start (circles: start, crosses: end),
    each placement drawn with both finger orders, like the mirrored map.
    """
    from ..plan.search import GraspMap, Search
    from ..simulation.status import Status

    if not isinstance(gmap, GraspMap):
        raise TypeError(f"plot_grasp_map draws a GraspMap (jaxsqueeze.grasp_map(scene, ...)), got "
                        f"{type(gmap).__name__}")
    if search is not None and not isinstance(search, Search):
        raise TypeError(f"search= takes a Search (jaxsqueeze.optimize_placement(scene, ...)), got "
                        f"{type(search).__name__}")
    if ax is None:
        fig = Figure(figsize=(6.4, 5.4), dpi=110)
        ax = fig.add_subplot()
    else:
        fig = ax.figure
    s = np.asarray(gmap.s) * MM
    step = s[1] - s[0] if len(s) > 1 else 1.0
    edges = np.append(s, s[-1] + step) - step / 2
    ok = np.asarray(gmap.status) == Status.SUCCESS
    q = np.ma.masked_where(~ok, np.asarray(gmap.quality))
    infeasible = np.ma.masked_where(ok, np.where(np.asarray(gmap.status) == Status.INFEASIBLE_GRIP, 0.0, 1.0))
    ax.pcolormesh(edges, edges, infeasible.T, cmap=ListedColormap(["0.88", "0.55"]), vmin=0, vmax=1)
    mesh = ax.pcolormesh(edges, edges, q.T, cmap="viridis")
    fig.colorbar(mesh, ax=ax, label=label)
    best = np.asarray(gmap.best)
    if len(best):
        ax.plot(best[:, 0] * MM, best[:, 1] * MM, "*", color="tab:orange", ms=10, mec="k", mew=0.5,
                label="best cells")
        ax.plot(best[0, 0] * MM, best[0, 1] * MM, "*", color="white", ms=14, mec="k", mew=0.8)
    if search is not None:
        for k, hist in enumerate(search.history):
            x = np.array([h.x for h in hist if not h.undone])          # the path the search took
            tried = np.array([h.x for h in hist if h.undone]).reshape(-1, 3)   # steps it undid
            for a, b in ((0, 1), (1, 0)):
                ax.plot(x[:, a] * MM, x[:, b] * MM, "-", color="tab:red", lw=1.2,
                        label="search" if (k, a) == (0, 0) else None)
                ax.plot(x[0, a] * MM, x[0, b] * MM, "o", color="tab:red", ms=4)
                ax.plot(x[-1, a] * MM, x[-1, b] * MM, "x", color="tab:red", ms=7)
                ax.plot(tried[:, a] * MM, tried[:, b] * MM, ".", color="0.3", ms=4,
                        label="undone steps" if (k, a) == (0, 0) and any(h.undone for hs in search.history
                                                                         for h in hs) else None)
    ax.set_xlabel("finger 0 position s₀ [mm]")
    ax.set_ylabel("finger 1 position s₁ [mm]")
    ax.set_title(f"grasp map: {label} (grey: infeasible or failed)")
    ax.set_aspect("equal")
    ax.set_xlim(edges[0], edges[-1])
    ax.set_ylim(edges[0], edges[-1])
    if len(best) or search is not None:
        ax.legend(loc="upper right", fontsize=8)
    return fig
