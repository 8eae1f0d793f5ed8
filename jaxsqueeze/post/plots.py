"""Matplotlib figures of a squeeze (the paper's Figs. 4–8).

Every function returns a :class:`matplotlib.figure.Figure` built directly (no pyplot, no
backend switch), so the module is safe to import anywhere; show a figure in a notebook by
leaving it as the cell's value, or save it with ``fig.savefig(path)``. Lengths are shown in
millimetres in the user's frame (``mesh.points + mesh.offset``).
"""
from __future__ import annotations

import os

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle
from matplotlib.tri import Triangulation

from ..numbers import flag, real_array
from . import cones, views
from .views import EVENT_LETTERS, FREE, SLIP_POS, STICK

MM = 1e3
STICK_COLOR = "tab:blue"
SLIP_COLOR = "tab:red"
FINGER_COLORS = ("tab:green", "tab:purple", "tab:orange")     # fingers 0, 1 and an adversary's pusher
EVENT_MARKERS = {"A": ("o", "tab:green"), "B": ("x", "black"), "C": ("^", "tab:red"), "D": ("v", "tab:blue")}
DPI = 110


def _radii(res, r: int, X, C, rad: float) -> np.ndarray:
    """(F,) radius [m] of each fingertip at row ``r``: the grasping fingers' ``res.radius``;
    an adversary's pusher (not stored in the result) from its contact nodes, which lie on its
    circle (0 when it touches none). X: (m, 2) deformed boundary nodes, C: (F, 2) centres [m],
    in one frame."""
    out = np.full(len(C), rad)
    if len(C) > 2:
        on = (np.asarray(res.modes[r]) > FREE) & (np.asarray(res.finger[r]) == 2)
        out[2] = float(np.median(np.linalg.norm(X[on] - C[2], axis=1))) if on.any() else 0.0
    return out


def _boundary_loops(mesh):
    return np.split(np.arange(mesh.m), np.cumsum(mesh.loops)[:-1])


def _title_state(res, row):
    r = views.row_index(res, row)
    rel = views.relative_depth(res)[r]
    share = f" ({100 * rel:.1f} %)" if np.isfinite(rel) else ""      # (no touch: no grip distance)
    push = float(np.asarray(res.push)[r]) if res.push is not None else 0.0
    return f"d = {float(res.depth[r]) * MM:.2f} mm{share}" + (f", push {push * MM:.2f} mm" if push > 0 else "")


def _depth_label(res, r) -> str:
    """The legend label of row r: its depth relative to the grip distance, or in mm where the
    fingertips never touched (no grip distance to relate it to)."""
    rel = views.relative_depth(res)[r]
    return f"d = {100 * rel:.1f} %" if np.isfinite(rel) else f"d = {float(np.asarray(res.depth)[r]) * MM:.2f} mm"


def _is_band(mesh) -> bool:
    return len(np.asarray(mesh.triangles)) == 0


def plot_deformed(res, mesh, row: int = -1, displacement=None, zoom=None, ax=None, title=None,
                  show_nodes=True, details=True, legend=True, forces=None, stress=None) -> Figure:
    """Deformed object, fingertips and contact modes at one recorded row (Fig. 4).

    Draws the undeformed outline (dashed), the deformed mesh (light triangles; the full
    field is known at the final row, or pass ``displacement`` (n, 2) e.g. from
    :func:`jaxsqueeze.views.row_displacement`; otherwise only the deformed boundary), the
    fingertips, and the contact nodes: stick (blue dots) and slip (red dots with an arrow
    along the fingertip in the slip direction; none for a frictionless scene, whose direction
    is not tracked: pass the scene as ``mesh``).

    Args:
        zoom: optional ((xmin, xmax), (ymin, ymax)) in mm, or a centre (x, y) [m, user frame]
            with a half width: ``((x, y), half)``.
        ax: draw into an existing Axes (the Figure returned is its figure).
        details: with a new figure (no ``ax`` or ``zoom``), add two close-ups of the
            contact regions, one per finger, to the right of the whole object.
        forces: draw each finger's total contact force as an arrow at its contact (black;
            the longer arrow is a quarter of the object's size). Default: on for a band
            (:class:`~jaxsqueeze.band.Band`, drawn as its deformed polyline through the
            nodes), off for a mesh.
        stress: colour the deformed triangles by their plane stress [Pa]
            (:func:`jaxsqueeze.views.row_stress`): ``"von_mises"``, ``"xx"``, ``"yy"`` or
            ``"xy"``, with a colour bar. Needs the scene of a solid mesh as ``mesh`` (it gives
            the material); at a row other than the last the field is rebuilt through
            ``scene.operator()`` unless ``displacement`` is given.
    """
    res = views.trimmed(res)
    obj = mesh
    mesh = views.check_object(res, obj)      # (a scene gives its mesh)
    # a frictionless squeeze labels every sliding contact slip+: its direction is not tracked
    arrows = getattr(obj, "friction_model", "coulomb") != "frictionless"
    zoom = _zoom(zoom)
    if displacement is not None:
        displacement = real_array(displacement, "displacement", "m")
        if displacement.shape != np.shape(mesh.points) or not np.all(np.isfinite(displacement)):
            raise ValueError(f"displacement must be finite (n, 2) = {np.shape(mesh.points)} nodal displacements [m] of "
                             f"the mesh, got shape {displacement.shape}; see jaxsqueeze.views.row_displacement")
    forces = _is_band(mesh) if forces is None else flag(forces, "forces")
    show_nodes, details = flag(show_nodes, "show_nodes"), flag(details, "details")
    if legend != "figure":                  # (the close-ups' figure-wide legend)
        legend = flag(legend, "legend")
    r = views.row_index(res, row)
    if stress is not None:
        if stress not in STRESS_NAMES:
            raise ValueError(f"stress = {stress!r}: expected one of {tuple(STRESS_NAMES)} or None")
        views.check_object(res, obj, "scene (stress= needs its material)", takes=("scene",))
        if _is_band(mesh):
            raise ValueError("stress= needs a solid mesh; a band has no triangles")
        if displacement is None:
            displacement = views.scene_field(res, obj, r)
    last = r == len(np.asarray(res.depth)) - 1
    # no fingertips to draw or zoom on when a placement never found its squeeze line (NaN centres)
    placed = bool(np.all(np.isfinite(np.asarray(res.centres[r], float))))
    if ax is None and zoom is None and details and placed:
        fig = Figure(figsize=(11, 7), dpi=DPI, layout="constrained")
        gs = fig.add_gridspec(2, 2, width_ratios=[1.6, 1.0])
        ax = fig.add_subplot(gs[:, 0])
        C = np.asarray(res.centres[r], float) + np.asarray(mesh.offset, float)
        h = 1.6 * float(res.radius)
        for f in (0, 1):
            sub = fig.add_subplot(gs[f == 0, 1])   # finger 1 (top of the object) on top
            # centre the close-up between the fingertip centre and its contact
            away = C[f] - np.asarray(mesh.offset, float)
            away = away / max(np.linalg.norm(away), 1e-300)
            plot_deformed(res, obj, r, displacement, zoom=(C[f] - away * float(res.radius), h), ax=sub,
                          title=f"finger {f} (close-up)", legend=False, forces=forces, stress=stress)
        plot_deformed(res, obj, r, displacement, ax=ax, title=title, show_nodes=show_nodes, legend="figure",
                      forces=forces, stress=stress)
        return fig
    if ax is None:
        fig = Figure(figsize=(8, 6.5), dpi=DPI, layout="constrained")
        ax = fig.add_subplot()
    else:
        fig = ax.figure
    off = np.asarray(mesh.offset, float)
    P = np.asarray(mesh.points, float) + off
    B = np.asarray(mesh.boundary)
    ub = np.asarray(res.boundary_displacement[r], float)
    if displacement is None and last and res.displacement is not None:
        displacement = np.asarray(res.displacement, float)
    # undeformed outline
    for lp in _boundary_loops(mesh):
        q = P[B[lp]]
        q = np.vstack([q, q[:1]]) * MM
        ax.plot(q[:, 0], q[:, 1], "--", color="0.45", lw=1.0, zorder=1)
    # deformed mesh or boundary
    if displacement is not None and not _is_band(mesh):
        X = P + np.asarray(displacement, float)
        tri = Triangulation(X[:, 0] * MM, X[:, 1] * MM, np.asarray(mesh.triangles))
        if stress is not None:
            _stress_colours(ax, tri, views.row_stress(res, obj, r, displacement=displacement), stress, legend)
        ax.triplot(tri, color="0.75", lw=0.4, zorder=2)
    for lp in _boundary_loops(mesh):
        q = P[B[lp]] + ub[lp]
        q = np.vstack([q, q[:1]]) * MM
        ax.plot(q[:, 0], q[:, 1], "-", color="0.15", lw=1.2, zorder=3)
    # fingertips
    C = np.asarray(res.centres[r], float) + off
    rad = float(res.radius)
    radii = _radii(res, r, P[B] + ub, C, rad)
    for f in range(len(C)) if placed else ():
        if radii[f] > 0:
            ax.add_patch(Circle(C[f] * MM, radii[f] * MM, facecolor=FINGER_COLORS[f], alpha=0.18,
                                edgecolor=FINGER_COLORS[f], lw=1.5, zorder=4))
        ax.plot(*(C[f] * MM), "+", color=FINGER_COLORS[f], ms=8, zorder=4)
        if zoom is None:   # label beyond the fingertip, away from the object
            away = C[f] - off
            away = away / max(np.linalg.norm(away), 1e-300)
            at = (C[f] + away * 1.6 * max(radii[f], 0.5 * rad)) * MM
            ax.text(*at, f"finger {f}" if f < 2 else "pusher (finger 2)", ha="center", va="center", fontsize=9,
                    color=FINGER_COLORS[f], zorder=5)
            ax.update_datalim([at + away * 0.5 * rad * MM])
    # contact nodes
    modes = np.asarray(res.modes[r])
    fg = np.asarray(res.finger[r])
    theta = np.asarray(res.theta[r], float)
    alpha = np.asarray(res.alpha[r], float)
    X_b = (P[B] + ub) * MM
    stick = modes == STICK
    slip = modes >= SLIP_POS
    if show_nodes:
        ax.plot(X_b[stick, 0], X_b[stick, 1], "o", color=STICK_COLOR, ms=4.5, zorder=6,
                label=f"stick ({int(stick.sum())})")
        ax.plot(X_b[slip, 0], X_b[slip, 1], "o", color=SLIP_COLOR, ms=4.5, zorder=6,
                label=f"slip ({int(slip.sum())}), " + ("arrow: slip direction" if arrows else "frictionless"))
        if slip.any() and arrows:
            k = np.flatnonzero(slip)
            world = theta[k] + alpha[fg[k]]
            sign = np.where(modes[k] == SLIP_POS, 1.0, -1.0)
            t = sign[:, None] * np.stack([-np.sin(world), np.cos(world)], axis=1)
            L = 0.3 * rad * MM
            if zoom is not None:   # arrows a tenth of the close-up's width
                L = 0.1 * float(np.diff(ax.get_xlim())[0]) if np.ndim(zoom[1]) != 0 else 0.2 * zoom[1] * MM
            ax.quiver(X_b[k, 0], X_b[k, 1], t[:, 0] * L, t[:, 1] * L, color=SLIP_COLOR, angles="xy",
                      scale_units="xy", scale=1, width=0.006, zorder=7)
    if forces:
        Fr = np.asarray(res.forces[r], float)
        on = modes > FREE
        tot = [Fr[on & (fg == f)].sum(axis=0) for f in range(len(C))]
        big = max(max(np.linalg.norm(t) for t in tot), 1e-300)
        scale = 0.25 * float(np.max(np.ptp(P, axis=0))) / big
        for f in range(len(C)):
            k = np.flatnonzero(on & (fg == f))
            if not k.size or not np.linalg.norm(tot[f]) > 0:
                continue
            at = X_b[k].mean(axis=0)
            ax.quiver(at[0], at[1], tot[f][0] * scale * MM, tot[f][1] * scale * MM, color="black", angles="xy",
                      scale_units="xy", scale=1, width=0.005, zorder=8)
            if zoom is None:
                ax.text(*(at + 0.5 * tot[f] * scale * MM), f" {np.linalg.norm(tot[f]):.3g} N", fontsize=8,
                        va="bottom", zorder=8)
    handles, labels = ax.get_legend_handles_labels()
    if forces:
        handles.append(Line2D([], [], color="black", marker=r"$\rightarrow$", ls="", ms=12))
        labels.append("contact force of each finger")
    handles += [Line2D([], [], ls="--", color="0.45"), Line2D([], [], color="0.15")]
    labels += ["undeformed outline", "deformed outline"]
    if legend == "figure":
        fig.legend(handles, labels, loc="outside lower center", ncol=len(labels), fontsize=9)
    elif legend:
        ax.legend(handles, labels, loc="best", fontsize=8, framealpha=0.9)
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    if zoom is not None:
        if np.ndim(zoom[1]) == 0:
            (cx, cy), h = zoom
            ax.set_xlim((cx - h) * MM, (cx + h) * MM)
            ax.set_ylim((cy - h) * MM, (cy + h) * MM)
        else:
            ax.set_xlim(*zoom[0])
            ax.set_ylim(*zoom[1])
    else:
        ax.autoscale_view()
    status = res.outcome.name if last else "in progress"
    what = "Deformed object" if stress is None else STRESS_NAMES[stress][0]
    ax.set_title(title or f"{what} at {_title_state(res, r)} — {status}")
    ax.grid(True, lw=0.3, alpha=0.5)
    return fig


#: plot_deformed's stress= choices: (label, column of row_stress or None for von Mises)
STRESS_NAMES = {"von_mises": ("von Mises stress", None), "xx": ("σ_xx", 0), "yy": ("σ_yy", 1), "xy": ("τ_xy", 2)}


def _stress_colours(ax, tri, sig, name, bar):
    """Fill the triangles by one stress value [Pa]: von Mises from white to black, a component
    on a diverging map centred on zero; a colour bar beside ``ax`` when ``bar``."""
    from ..mechanics.fem import von_mises

    label, col = STRESS_NAMES[name]
    if col is None:
        v, cmap, lo, hi = np.asarray(von_mises(sig), float), "Greys", 0.0, None
    else:
        v, cmap = sig[:, col], "PuOr_r"
        hi = max(float(np.abs(v).max(initial=0.0)), 1e-300)
        lo = -hi
    art = ax.tripcolor(tri, facecolors=v, cmap=cmap, vmin=lo, vmax=hi, alpha=0.8, zorder=1.5)
    if bar:
        ax.figure.colorbar(art, ax=ax, label=f"{label} [Pa]", shrink=0.8)


def _zoom(zoom):
    """``zoom`` of :func:`plot_deformed` checked: None, ((xmin, xmax), (ymin, ymax)) [mm] with
    xmin < xmax and ymin < ymax, or ((x, y) [m], half width [m] > 0); all finite."""
    if zoom is None:
        return None
    try:
        a, b = (np.asarray(z, float) for z in zoom)
    except (TypeError, ValueError):
        a = b = None
    box = a is not None and a.shape == (2,) and b.shape == (2,) and a[0] < a[1] and b[0] < b[1]
    centre = a is not None and a.shape == (2,) and b.shape == () and b > 0
    if not (box or centre) or not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise ValueError(f"zoom={zoom!r}: expected ((xmin, xmax), (ymin, ymax)) in mm with min < max, or a centre "
                         "and half width ((x, y), half) in m with half > 0, all finite")
    return (tuple(a), tuple(b)) if box else (tuple(a), float(b))


def default_rows(res, count: int = 4) -> list[int]:
    """Rows nearest to evenly spaced fractions of the final depth (1/count ... 1)."""
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise ValueError(f"count={count!r}: expected an integer >= 1 (how many rows)")
    res = views.trimmed(res)
    depth = np.asarray(res.depth, float)
    targets = depth[-1] * np.arange(1, count + 1) / count
    rows = sorted({int(np.argmin(np.abs(depth - t))) for t in targets})
    return [r for r in rows if depth[r] > 0] or [len(depth) - 1]


def plot_force_profile(res, rows=None, mesh=None, degrees=True, smooth=True) -> Figure:
    """Fig. 5 analogue: force density (top) and force direction (bottom) against arc length
    along the contact, finger 0 (left) and finger 1 (right), one curve per selected row.

    ``rows`` (row indices, or one) defaults to the rows nearest 25, 50, 75 and 100 % of the final depth. Markers
    are nodal values (filled: stick, open: slip); lines are cubic splines through them.
    """
    res = views.trimmed(res)
    degrees, smooth = flag(degrees, "degrees"), flag(smooth, "smooth")
    mesh = None if mesh is None else views.check_object(res, mesh)
    if isinstance(rows, (int, np.integer)) and not isinstance(rows, (bool, np.bool_)):
        rows = [rows]                                      # one row
    rows = default_rows(res) if rows is None else [views.row_index(res, r) for r in rows]
    if not rows:
        raise ValueError("rows is empty: name at least one recorded row, or pass rows=None for the rows "
                         "nearest 25, 50, 75 and 100 % of the final depth")
    fig = Figure(figsize=(10, 7), dpi=DPI, layout="constrained")
    axs = fig.subplots(2, 2, sharex="col")
    cmap = _cmap(len(rows))
    for f in (0, 1):
        drawn = False
        for c, r in zip(cmap, rows):
            p = views.force_profile(res, r, f, mesh=mesh)
            if not len(p.s):
                continue
            drawn = True
            s = p.s * MM
            ang = np.degrees(p.angle) if degrees else p.angle
            label = _depth_label(res, r)
            for ax, y in ((axs[0, f], p.density), (axs[1, f], ang)):
                if smooth:
                    xs, ys = views.spline(s, y)
                    ax.plot(xs, ys, "-", color=c, lw=1.5, label=label)
                else:
                    ax.plot(s, y, "-", color=c, lw=1.5, label=label)
                st = p.modes == STICK
                ax.plot(s[st], y[st], "o", color=c, ms=4)
                ax.plot(s[~st], y[~st], "o", mfc="white", mec=c, ms=4)
        axs[0, f].set_title(f"Finger {f}")
        if not drawn:
            for ax in axs[:, f]:
                ax.text(0.5, 0.5, "no contact", transform=ax.transAxes, ha="center", va="center", color="0.4")
        axs[0, f].set_ylabel("force density [N/m]")
        axs[1, f].set_ylabel("force direction [deg]" if degrees else "force direction [rad]")
        axs[1, f].set_xlabel("arc length along fingertip s [mm]")
        for ax in axs[:, f]:
            ax.grid(True, lw=0.3, alpha=0.6)
    handles = [Line2D([], [], color=c, lw=1.5) for c in cmap]
    labels = [_depth_label(res, r) for r in rows]
    handles += [Line2D([], [], ls="", marker="o", color="0.3"),
                Line2D([], [], ls="", marker="o", mfc="white", mec="0.3")]
    labels += ["stick node", "slip node"]
    fig.legend(handles, labels, fontsize=9, loc="outside right upper")
    fig.suptitle("Force profile (relative squeeze depth d / D0)")
    return fig


def plot_sliding_profile(res, degrees=True) -> Figure:
    """Fig. 6 analogue: polar angle of every contact node against relative depth, per finger.

    Grey-blue line segments: the node sticks (its angle stays fixed); red: it slides.
    Markers: C (stick→slip, ▲) and D (slip→stick, ▼) events. The squeeze's rows only: an
    adversary's push rows all lie at the final depth (the title counts them).
    """
    res = views.trimmed(res)
    degrees = flag(degrees, "degrees")
    fig = Figure(figsize=(10, 5.5), dpi=DPI, layout="constrained")
    axs = fig.subplots(1, 2)
    ev = views.event_table(res)
    squeeze = np.asarray(res.push) == 0        # an adversary's push rows share the final depth: left out
    for f, ax in zip((0, 1), axs):
        sp = views.sliding_profile(res, f)
        x = 100 * sp.relative_depth[squeeze]
        th = np.degrees(sp.theta) if degrees else sp.theta
        th, modes = th[squeeze], sp.modes[squeeze]
        for c in range(len(sp.nodes)):
            y, md = th[:, c], modes[:, c]
            seg = np.stack([np.stack([x[:-1], y[:-1]], 1), np.stack([x[1:], y[1:]], 1)], 1)
            ok = np.isfinite(seg).all(axis=(1, 2))
            sl = md[1:] >= SLIP_POS
            for mask, color, lw in ((ok & ~sl, STICK_COLOR, 1.0), (ok & sl, SLIP_COLOR, 1.8)):
                if mask.any():
                    ax.add_collection(LineCollection(seg[mask], colors=color, linewidths=lw))
        for e in ev:
            if e["finger"] != f or e["kind"] not in "CD" or e["phase"] != "squeeze":
                continue
            c = np.flatnonzero(sp.nodes == e["node"])
            if not c.size:
                continue
            k = int(np.argmin(np.abs(sp.depth[squeeze] - e["depth"])))
            mk, col = EVENT_MARKERS[e["kind"]]
            ax.plot(100 * e["relative_depth"], th[k, c[0]], mk, color=col, ms=6, mec="k", mew=0.5)
        ax.autoscale_view()
        ax.set_xlabel("relative squeeze depth d / D0 [%]")
        ax.set_ylabel("polar angle of contact node [deg]" if degrees else "polar angle [rad]")
        ax.set_title(f"Finger {f}: {len(sp.nodes)} nodes touched")
        ax.grid(True, lw=0.3, alpha=0.6)
    axs[1].legend([Line2D([], [], color=STICK_COLOR), Line2D([], [], color=SLIP_COLOR, lw=1.8),
                   Line2D([], [], ls="", marker="^", color=EVENT_MARKERS["C"][1], mec="k"),
                   Line2D([], [], ls="", marker="v", color=EVENT_MARKERS["D"][1], mec="k")],
                  ["sticking", "sliding", "event C (stick→slip)", "event D (slip→stick)"],
                  fontsize=8, loc="best")
    pushed = "" if squeeze.all() else f" (the squeeze; the push's {int((~squeeze).sum())} rows are not drawn)"
    fig.suptitle("Sliding profile: polar angle about the fingertip centre" + pushed)
    return fig


def plot_events(res) -> Figure:
    """Timeline of the squeeze's contact events: depth on x, mesh node on y, one panel per
    finger and one marker per kind (A ●, B ×, C ▲, D ▼); an adversary's push events, at the
    final depth, are counted in the title (``result.events.rows()`` lists them)."""
    res = views.trimmed(res)
    fig = Figure(figsize=(9, 6), dpi=DPI, layout="constrained")
    axs = fig.subplots(2, 1, sharex=True)
    table = views.event_table(res)
    ev = [e for e in table if e["phase"] == "squeeze"]      # (depth is the squeeze's)
    pushed = len(table) - len(ev)
    for f, ax in zip((1, 0), axs):          # finger 1 (top of the object) on top
        for kind, (mk, col) in EVENT_MARKERS.items():
            sel = [e for e in ev if e["kind"] == kind and e["finger"] == f]
            if sel:
                ax.plot([e["depth"] * MM for e in sel], [e["node"] for e in sel], mk, ls="",
                        color=col, ms=7, label=f"{kind}: {views.EVENT_MEANING[kind]} ({len(sel)})")
        ax.set_ylabel(f"finger {f}: mesh node")
        ax.grid(True, lw=0.3, alpha=0.6)
        if any(e["finger"] == f for e in ev):
            ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
        else:
            ax.text(0.5, 0.5, "no events", transform=ax.transAxes, ha="center")
    axs[1].set_xlabel("squeeze depth d [mm]")
    last = float(np.asarray(res.depth)[-1]) * MM
    if last > 0:                   # (a squeeze that ended at its first touch has one depth, 0)
        axs[1].set_xlim(0, last * 1.02)
    seq = "".join(e["kind"] for e in ev)
    counts = ", ".join(f"{k}: {seq.count(k)}" for k in EVENT_LETTERS)
    push = f"\nand {pushed} in the adversary's push (result.events.rows(), summary.json)" if pushed else ""
    fig.suptitle(f"Contact events of the squeeze ({len(ev)} in all; {counts}){push}")
    return fig


def _cmap(k):
    from matplotlib import colormaps

    cm = colormaps["viridis"]
    return [cm(v) for v in np.linspace(0.0, 0.85, max(k, 1))]


def save_all(res, scene, outdir) -> dict:
    """Write deformed.png, force_profile.png, sliding_profile.png and events.png to ``outdir``;
    for a solid object with a finite final field also stress.png (the deformed object coloured
    by von Mises stress), for a band cones.png (:func:`plot_cone_rotation`).

    Returns {name: path}.
    """
    res = views.trimmed(res)
    views.check_object(res, scene, "scene", takes=("scene",))
    outdir = views.make_folder(outdir)
    mesh = scene.mesh
    figs = dict(deformed=plot_deformed(res, scene), force_profile=plot_force_profile(res, mesh=mesh),
                sliding_profile=plot_sliding_profile(res), events=plot_events(res))
    u = res.displacement
    if not _is_band(mesh) and u is not None and np.all(np.isfinite(np.asarray(u))):
        figs["stress"] = plot_deformed(res, scene, stress="von_mises")
    if _is_band(mesh) and scene.friction_model == "coulomb":
        figs["cones"] = plot_cone_rotation(res, scene)      # Fig. 3: friction-cone rotation
    out = {}
    for name, fig in figs.items():
        path = os.path.join(outdir, f"{name}.png")
        fig.savefig(path)
        out[name] = path
    return out


def plot_cone_rotation(res, obj, axis: str = "surface", friction: float | None = None):
    """Fig. 3 analogue: the cones at the start and at the end, their rotation toward the
    other finger and the cone margins against the relative depth.

    Left: the deformed object near the two contacts with the friction cones (initial:
    dashed, final: solid) and the force directions. Middle: ``toward`` [deg] per finger.
    Right: cone margin [deg] per finger (0 = on the cone edge: slip). Returns a Figure.
    """
    res = views.trimmed(res)
    st = cones.grasp_stability(res, obj, axis=axis, friction=friction)
    c = st.cones
    geo, op, _, mu = cones.unpack(obj)
    mu = float(friction) if friction is not None else mu
    P, loops = cones.boundary_geometry(geo, op)
    off = np.asarray(getattr(geo, "offset", np.zeros(2)), float)
    fig = Figure(figsize=(14, 4.6), dpi=DPI, layout="constrained")
    a0, a1, a2 = fig.subplots(1, 3, width_ratios=[1.2, 1, 1])
    # --- geometry with cones
    U = np.asarray(res.boundary_displacement, float)
    start = 0
    for n in loops:
        for r, style in ((0, "--"), (-1, "-")):
            q = P[start:start + n] + U[r, start:start + n] + off
            q = np.vstack([q, q[:1]]) * MM
            a0.plot(q[:, 0], q[:, 1], style, color="0.5" if r == 0 else "0.15", lw=1.0)
        start += n
    half = np.arctan(mu)
    size = 0.12 * float(np.max(np.ptp(P, axis=0)))
    for f in (0, 1):
        for r, style, alpha in ((0, "--", 0.10), (-1, "-", 0.22)):
            p, a = c.contact[r, f] + off, c.axis[r, f]
            if not np.all(np.isfinite(a)):
                continue
            e1, e2 = cones.rotate(a, half), cones.rotate(a, -half)
            tri = np.array([p, p + size * e1, p + size * e2]) * MM
            a0.fill(tri[:, 0], tri[:, 1], color=FINGER_COLORS[f], alpha=alpha, lw=0)
            a0.plot(*(np.array([p, p + size * a]) * MM).T, style, color=FINGER_COLORS[f], lw=1.2)
        p, fd = c.contact[-1, f] + off, cones.unit_vector(c.force[-1, f])
        a0.annotate("", xy=(p + 0.8 * size * fd) * MM, xytext=p * MM,
                    arrowprops=dict(arrowstyle="->", color="k", lw=1.4))
        a0.add_patch(Circle(
            (np.asarray(res.centres[-1, f], float) + off) * MM, float(res.radius) * MM,
            facecolor=FINGER_COLORS[f], alpha=0.3, edgecolor=FINGER_COLORS[f]))
    a0.set_aspect("equal")
    a0.set_xlabel("x [mm]")
    a0.set_ylabel("y [mm]")
    a0.set_title(f"friction cones ({c.kind} axis)\nstart: dashed, end: solid; arrows: forces", fontsize=10)
    a0.grid(True, lw=0.3, alpha=0.5)
    x = 100 * c.relative_depth
    for f in (0, 1):
        a1.plot(x, np.degrees(c.toward[:, f]), "-", color=FINGER_COLORS[f], lw=1.6,
                label=f"finger {f}: {st.finger_labels[f]}")
        a2.plot(x, np.degrees(c.margin[:, f]), "-", color=FINGER_COLORS[f], lw=1.6, label=f"finger {f}")
    a2.axhline(0.0, color="tab:red", lw=1.0, ls=":", label="cone edge (slip)")
    a1.axhline(0.0, color="0.5", lw=0.8)
    a1.set_xlabel("relative squeeze depth d / D0 [%]")
    a1.set_ylabel("cone rotation toward the other finger [deg]")
    a1.set_title(f"cone rotation: {st.label}")
    a2.set_xlabel("relative squeeze depth d / D0 [%]")
    a2.set_ylabel("cone margin atan(mu) - angle(F, axis) [deg]")
    a2.set_title("margin of the force inside its cone")
    for a in (a1, a2):
        a.grid(True, lw=0.3, alpha=0.6)
        a.legend(fontsize=8, loc="best")
    return fig
