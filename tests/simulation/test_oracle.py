"""Whole squeezes against an independent NumPy oracle of the paper (tests/squeeze_oracle.py).

The oracle shares no code with the engine: its own CST assembly, the paper's compliance (dense
eigendecomposition of K, the three rigid modes dropped), its own bordered solve (eq. 4),
slip-angle Newton (eq. 6) and event location by bisection on the depth. Both must give the same
outcome, final depth, per-node contact forces (1e-6 of the largest), contact nodes, fingers and
stick/slip modes, and the same event sequence (kind, node, finger) at the same depths (1e-6 L;
they agree to ~1e-12 L). With turning fingertips (``rotation``) the oracle puts a node at world
angle theta + alpha_f(d): a sticking node keeps its finger-frame angle theta, and D watches the
slip relative to the tip; the finger-frame angles (``res.theta``) must agree too. Point contacts
(``contact="point"``: no event A, the cone about the deformed surface normal) and the adversary
push (a third tip after the squeeze, with its qualities) are compared the same way. Meshes stay
below ~200 nodes and share one compiled program per feature, so that the module runs in seconds.
"""
import numpy as np
import pytest

import jaxsqueeze as jsq
from jaxsqueeze.plan import quality
from physics import check_states, replay_events, sliding_against_friction, symmetric_square
from squeeze_oracle import from_mesh

E, NU, H = 1e5, 0.3, 0.0254
CENTRED = ((0.0, -0.05), (0.0, 0.05))
SLANTED = ((-0.005, -0.05), (0.005, 0.05))


def _meshes():
    return {
        # 146 nodes, 40 on the boundary, 3 mm edges at the slanted grip points
        "square": jsq.shapes.rectangle(0.1, 0.1, max_edge=0.025, refine_near=[list(p) for p in SLANTED],
                                       refine_edge=0.003, refine_radius=0.003),
        "symmetric": symmetric_square(0.1, 0.01),       # 141 nodes, mirror-symmetric
        # 172 nodes, 2.5 mm edges at the slanted grip points
        "disk": jsq.shapes.disk(0.05, max_edge=0.02, refine_near=[list(p) for p in SLANTED], refine_edge=0.0025,
                                refine_radius=0.005),
        # 148 nodes, two boundary loops (40 outer, 14 on a 40 mm square hole): the hole's nodes
        # are boundary nodes that never touch a fingertip, and the rigid modes see both loops
        "holed": jsq.shapes.polygon([(-0.05, -0.05), (0.05, -0.05), (0.05, 0.05), (-0.05, 0.05)],
                                    holes=[[(-0.02, -0.02), (-0.02, 0.02), (0.02, 0.02), (0.02, -0.02)]],
                                    max_edge=0.025, refine_near=[list(p) for p in SLANTED], refine_edge=0.003,
                                    refine_radius=0.003),
    }


@pytest.fixture(scope="module")
def meshes():
    with pytest.warns(UserWarning, match=r"two elements thick .*\(the thinnest 0.03 m"):   # the holed square's walls:
        return _meshes()                                                                 # coarse on purpose


# (mesh, grip points, friction model, mu, fingertip radius [m], depth [m], events expected)
CASES = {
    "coulomb mu=0.15 (A, C, D events)": ("square", SLANTED, "coulomb", 0.15, 0.02, 0.015, "ACD"),
    "coulomb mu=0.2": ("square", SLANTED, "coulomb", 0.2, 0.02, 0.015, "ACD"),
    "coulomb mu=0.5": ("square", SLANTED, "coulomb", 0.5, 0.01, 0.015, "A"),
    "stick (mu = inf)": ("square", SLANTED, "stick", np.inf, 0.02, 0.015, "A"),
    "coulomb symmetric": ("symmetric", CENTRED, "coulomb", 0.2, 0.03, 0.015, "A"),
    "frictionless symmetric": ("symmetric", CENTRED, "frictionless", 0.0, 0.03, 0.015, "A"),
    "coulomb holed square (A, C, D)": ("holed", SLANTED, "coulomb", 0.25, 0.03, 0.015, "ACD"),
}


def _canonical(events, L, tie=1e-9):
    """Events in order; those at one depth (mirror-symmetric pairs) sorted by kind and node."""
    out, group = [], []
    for e in events:
        if group and abs(e[2] - group[0][2]) > tie * L:
            out += sorted(group, key=lambda x: (x[0], x[1]))
            group = []
        group.append(e)
    return out + sorted(group, key=lambda x: (x[0], x[1]))


def _agree(res, o, L, kinds, modes=True):
    """Assert that the library's end state and event log equal the oracle's: per-node and
    per-finger forces (1e-6 of the largest the squeeze recorded: after a break that left one
    finger without contact the end forces are round-off), contact set, fingers, modes (``modes=False``: only
    that every contact slides, the frictionless label), finger-frame angles, and the events
    (kind, node, finger) with their depths (1e-6 L), squeeze and push phase each in order with
    ties at one depth sorted. ``kinds``: the oracle's event kinds, a set or the exact string."""
    F = np.asarray(res.final_forces)
    scale = max(np.abs(o.forces).max(), np.abs(np.asarray(res.finger_forces)).max())
    np.testing.assert_allclose(F, o.forces, rtol=0, atol=1e-6 * scale)
    nf = len(o.total_force)
    np.testing.assert_allclose(np.asarray(res.finger_forces[-1])[:nf], o.total_force, rtol=0, atol=1e-6 * scale)
    mode, finger = np.asarray(res.modes[-1]), np.asarray(res.finger[-1])
    on = mode > 0
    assert np.array_equal(on, o.modes > 0), "contact sets differ"
    assert np.array_equal(finger[on], o.finger[on]), "contact fingers differ"
    if modes:
        assert np.array_equal(mode, o.modes), "stick/slip modes differ"
    else:
        assert np.all(mode[on] >= 2)
    dth = np.angle(np.exp(1j * (np.asarray(res.theta[-1]) - o.theta)))[on]    # finger frame, modulo 2 pi
    assert np.abs(dth).max(initial=0) <= 1e-6
    k = int(res.squeeze_events)
    assert k == o.squeeze_events
    ev_l = [(kind, n, d, f) for d, n, kind, f in res.events.rows()]
    ev_o = [(e.kind, e.node, e.depth, e.finger) for e in o.events]
    ev_l = _canonical(ev_l[:k], L) + _canonical(ev_l[k:], L)
    ev_o = _canonical(ev_o[:k], L) + _canonical(ev_o[k:], L)
    assert [(kind, n, f) for kind, n, _, f in ev_l] == [(kind, n, f) for kind, n, _, f in ev_o]
    assert max((abs(a[2] - b[2]) for a, b in zip(ev_l, ev_o)), default=0.0) <= 1e-6 * L
    got = "".join(kind for kind, *_ in ev_o)
    assert (set(got) == kinds) if isinstance(kinds, set) else (got == kinds)


@pytest.mark.parametrize("name", list(CASES))
def test_squeeze_matches_the_oracle(meshes, name):
    key, pts, model, mu, radius, depth, kinds = CASES[name]
    mesh = meshes[key]
    grip = (jsq.scene.nearest_boundary_node(mesh, pts[0]), jsq.scene.nearest_boundary_node(mesh, pts[1]))
    scene = jsq.Scene(mesh=mesh, material=jsq.Material(E=E, nu=NU, thickness=H), fingers=jsq.Fingers(radius=radius),
                      grip=grip, friction=0.5 if np.isinf(mu) else mu, depth=depth, friction_model=model)
    res = jsq.squeeze(scene)
    o = from_mesh(mesh, E, NU, H, radius, grip, mu, depth, model=model)
    L = float(np.ptp(mesh.points, axis=0).max())

    assert res.outcome.name == o.status == "SUCCESS"
    assert abs(float(res.final_depth) - o.final_depth) <= 1e-9 * L
    assert np.array_equal(np.asarray(res.nodes), o.nodes)

    _agree(res, o, L, set(kinds), modes=model != "frictionless")
    replay_events(res, frictionless=model == "frictionless")      # the log holds every mode change


@pytest.mark.parametrize("radius, mu, kinds", [(1e3, 0.2, "AAACACCC"), (3e3, 0.15, "ACACACACC")])
def test_a_flat_pad_takes_its_contacts_one_touch_at_a_time(meshes, radius, mu, kinds):
    """Fingertips of radius 1,000 and 3,000 m on the slanted grip of the square (default
    settings: event_tol 1e-8 m): the neighbours touch 0.2 to 1.1 nm apart at depths of 7 to
    23 nm, inside one event bracket and below its width. Joined all at the first touch, the
    later ones pulled there, the stick hypothesis judged all four outside their cones (1,000 m:
    A A A A C C C C at one depth) and the grip nodes slid out; each now joins at its own touch,
    and every event is located to 1e-4 of its depth where that is finer than event_tol
    (docs/numerics.md §2, 31; 3,000 m at mu = 0.15 failed at 7.6 nm instead of 13.3 nm). As in
    the oracle, which bisects each event to 1e-12 L: the same events, then the grip node of
    finger 1 slides with no sticking neighbour left, SLIP_FAILURE. The depths agree to 1.5e-10 L
    (the gap of a tip 1e4 L wide is rounded to R eps), the forces at the end to 2e-4 (force
    grows with depth: 4e-5 N at 67 nm)."""
    mesh = meshes["square"]
    grip = (jsq.scene.nearest_boundary_node(mesh, SLANTED[0]), jsq.scene.nearest_boundary_node(mesh, SLANTED[1]))
    with pytest.warns(UserWarning, match=r"radius \(\d+ m\) and the object \(0.1 m across\) differ.* near-flat pad"):
        res = jsq.squeeze(jsq.Scene(mesh=mesh, material=jsq.Material(E=E, nu=NU, thickness=H),
                                    fingers=jsq.Fingers(radius=radius), grip=grip, friction=mu, depth=0.005))
    o = from_mesh(mesh, E, NU, H, radius, grip, mu, 0.005)
    L = float(np.ptp(mesh.points, axis=0).max())
    assert res.outcome.name == o.status == "SLIP_FAILURE"
    ev_l, ev_o = res.events.rows(), o.events
    assert [(k, n, f) for _, n, k, f in ev_l] == [(e.kind, e.node, e.finger) for e in ev_o]
    assert "".join(k for _, _, k, _ in ev_l) == kinds
    assert len({d for d, _, k, _ in ev_l if k == "A"}) == 4                # four touches, four depths
    assert max(abs(a[0] - b.depth) for a, b in zip(ev_l, ev_o)) <= 1e-9 * L
    assert abs(float(res.final_depth) - o.final_depth) <= 1e-9 * L
    mode = np.asarray(res.modes[-1])
    assert np.array_equal(mode, o.modes) and np.array_equal(np.asarray(res.finger[-1])[mode > 0], o.finger[mode > 0])
    np.testing.assert_allclose(np.asarray(res.finger_forces[-1]), o.total_force, rtol=1e-3)


def test_a_flat_pad_that_holds_matches_the_oracle(meshes):
    """A 3,000 m fingertip at mu = 0.2 on the slanted grip of the square holds to 5 mm, with
    70 events as in the oracle, to the oracle's forces and modes. At 79 nm a contact joined
    there with the default gap_tol's push (1e-10 m: 1e-3 of the forces at that depth), which
    set a neighbour that D had just stuck outside its cone for ~1e-10 m of squeeze; the rule
    that slides an older stick contact outside its cone slid it at once, the sequences parted,
    and the end forces differed by 4 % across the squeeze line. It now slides one that is
    still outside at the probe depth only (docs/numerics.md §2, 30 and 31)."""
    mesh = meshes["square"]
    grip = (jsq.scene.nearest_boundary_node(mesh, SLANTED[0]), jsq.scene.nearest_boundary_node(mesh, SLANTED[1]))
    with pytest.warns(UserWarning, match="near-flat pad"):
        res = jsq.squeeze(jsq.Scene(mesh=mesh, material=jsq.Material(E=E, nu=NU, thickness=H),
                                    fingers=jsq.Fingers(radius=3e3), grip=grip, friction=0.2, depth=0.005))
    o = from_mesh(mesh, E, NU, H, 3e3, grip, 0.2, 0.005)
    L = float(np.ptp(mesh.points, axis=0).max())
    assert res.outcome.name == o.status == "SUCCESS" and len(res.events.rows()) == 70
    _agree(res, o, L, {"A", "C", "D"})


def test_slip_reversal_at_a_new_contact_gives_event_d(meshes):
    """Disk R = 50 mm, fingertips r = 40 mm, mu = 0.15. When node 11 joins finger 0 at
    d = 3.798 mm, its neighbour node 12, sliding toward smaller polar angles (mode 3), must
    stop: its slip rate reverses (toward larger angles, against its friction), so it sticks
    there (event D at the depth of the A). The engine once let it slide on, its angle growing
    while its friction pushed it the same way, until d = 7.22 mm, and ended with forces 1.4e-5
    off the oracle's (ADVANCE only sees rates that change sign within a step)."""
    mesh = meshes["disk"]
    grip, mu, radius, depth = (13, 34), 0.15, 0.04, 0.013084016114332804
    scene = jsq.Scene(mesh=mesh, material=jsq.Material(E=E, nu=NU, thickness=H), fingers=jsq.Fingers(radius=radius),
                      grip=grip, friction=mu, depth=depth)
    res = jsq.squeeze(scene)
    assert sliding_against_friction(res).size == 0, "a node slides against its friction"
    o = from_mesh(mesh, E, NU, H, radius, grip, mu, depth)
    np.testing.assert_allclose(np.asarray(res.final_forces), o.forces, rtol=0, atol=1e-6 * np.abs(o.forces).max())
    L = float(np.ptp(mesh.points, axis=0).max())
    ev_l = _canonical([(k, n, d, f) for d, n, k, f in res.events.rows()], L)
    ev_o = _canonical([(e.kind, e.node, e.depth, e.finger) for e in o.events], L)
    assert [e[:2] for e in ev_l] == [e[:2] for e in ev_o]
    assert ("A", 11) in [e[:2] for e in ev_l] and ("D", 12) in [e[:2] for e in ev_l]


# ----------------------------------------------------------------------------- turning fingertips (Section IV-D)
# (mu, radius [m], depth [m], rotation coefficients (highest power first, d in m), outcome, event kinds);
# one radius, depth and coefficient shape (2, 3), so that the library compiles the squeeze once
ROTATING = {
    # at d = 9.67 mm node 31 joins and two sliding nodes (6, 7) both reverse: sticking 7 alone is
    # consistent (6's rate turns positive), sticking both leaves 6 on its cone edge turning out
    "mu=0.15 tips turn opposite ways (A, B, C, D; D at an event depth)":
        (0.15, 0.02, 0.015, [[0.0, -40.0, 0.0], [0.0, 40.0, 0.0]], "SUCCESS", "ABCD"),
    "mu=0.3 quadratic schedules": (0.3, 0.02, 0.015, [[2000.0, 10.0, 0.0], [-1500.0, 20.0, 0.0]], "SUCCESS", "ABC"),
    "mu=0.15 tips turn apart, with offsets": (0.15, 0.02, 0.015, [[0.0, 30.0, 0.3], [0.0, -30.0, 1.0]], "SUCCESS", "ABCD"),
}


def _turning(mesh, nu, radius, grip, mu, depth, rot, model="coulomb", contact="segment", step=None):
    """The scene with fingertips turning by ``rot`` (2, k), the library's squeeze of it, the
    oracle's (``step``: its step, default depth / 50) and L. Full stick: ``model="stick"``."""
    stick = model == "stick"
    scene = jsq.Scene(mesh=mesh, material=jsq.Material(E=E, nu=nu, thickness=H), friction_model=model,
                      contact=contact, fingers=jsq.Fingers(radius=radius, rotation=rot), grip=grip,
                      friction=0.5 if stick else mu, depth=depth)
    o = from_mesh(mesh, E, nu, H, radius, grip, np.inf if stick else mu, depth, model=model, rotation=rot,
                  contact=contact, step=step)
    return scene, jsq.squeeze(scene), o, float(np.ptp(mesh.points, axis=0).max())


@pytest.mark.parametrize("name", list(ROTATING))
def test_rotating_squeeze_matches_the_oracle(meshes, name):
    mu, radius, depth, rot, outcome, kinds = ROTATING[name]
    mesh = meshes["square"]
    grip = (jsq.scene.nearest_boundary_node(mesh, SLANTED[0]), jsq.scene.nearest_boundary_node(mesh, SLANTED[1]))
    _, res, o, L = _turning(mesh, NU, radius, grip, mu, depth, rot)

    assert res.outcome.name == o.status == outcome
    assert abs(float(res.final_depth) - o.final_depth) <= 1e-9 * L
    assert np.array_equal(np.asarray(res.nodes), o.nodes)
    np.testing.assert_allclose(np.asarray(res.alpha[-1])[:2], [np.polyval(c, o.final_depth) for c in rot], atol=1e-12)

    _agree(res, o, L, set(kinds))


def test_a_constant_rotation_offset_changes_nothing_physical(meshes):
    """rotation = [[0, 0, c0], [0, 0, c1]]: the tips start turned and never turn, so forces and
    events equal the unturned squeeze's and the finger-frame angles shift by -c."""
    mesh = meshes["square"]
    grip = (jsq.scene.nearest_boundary_node(mesh, SLANTED[0]), jsq.scene.nearest_boundary_node(mesh, SLANTED[1]))
    base = jsq.Scene(mesh=mesh, material=jsq.Material(E=E, nu=NU, thickness=H), fingers=jsq.Fingers(radius=0.02),
                     grip=grip, friction=0.3, depth=0.015)
    c = (0.4, -0.7)
    a = jsq.squeeze(base)
    b = jsq.squeeze(base.replace(fingers=jsq.Fingers(radius=0.02, rotation=[[0.0, 0.0, c[0]], [0.0, 0.0, c[1]]])))
    np.testing.assert_allclose(b.final_forces, a.final_forces, rtol=0, atol=1e-9 * np.abs(a.final_forces).max())
    assert [e[1:] for e in a.events.rows()] == [e[1:] for e in b.events.rows()] and len(a.events.rows()) > 0
    on = np.asarray(a.modes[-1]) > 0
    shift = np.angle(np.exp(1j * (np.asarray(b.theta[-1]) - np.asarray(a.theta[-1]) +
                                  np.asarray(c)[np.asarray(a.finger[-1])])))[on]
    assert np.abs(shift).max() <= 1e-9


# ----------------------------------------------------------------------------- point contacts and the adversary push
# (grip, mu, radius, depth, outcome, final depth [m] or None (= depth), event kinds)
POINT = {
    # the slanted grip of test_oracle.py: the surface cones turn toward the grip segment, no event
    "slanted mu=0.3 holds": ((7, 27), 0.3, 0.02, 0.015, "SUCCESS", "" ),
    # corner-side grip, mu just above the initial misalignment: the cone of finger 0's contact turns
    # away and its edge reaches the force at 0.481 mm (C, then SLIP_FAILURE)
    "grip (28, 6) mu=0.0843 fails by C": ((28, 6), 0.08431295773232896, 0.02, 0.01417, "SLIP_FAILURE", "C"),
    # on the refined disk other nodes have sunk into the tips (as point contacts allow) when C
    # fires: a guard for segment contacts once read that as STALLED
    "disk grip (26, 4) mu=0.1365 fails by C with sunk nodes": ((26, 4), 0.1365, 0.02, 0.0143, "SLIP_FAILURE", "C"),
    # full stick, a grip 84 degrees off finger 0's normal (near a corner of the bottom side): the
    # surface there turns under the squeeze until the force leaves the cone's half-plane through
    # its apex (B about the surface normal, the cone's axis; about the tip normal it would hold)
    "stick grip (13, 39) breaks as the surface turns": ((13, 39), np.inf, 0.01, 0.015, "LOST_CONTACT", "B"),
}


@pytest.mark.parametrize("name", list(POINT))
def test_point_contacts_match_the_oracle(meshes, name):
    grip, mu, radius, depth, outcome, kinds = POINT[name]
    square = meshes["disk" if name.startswith("disk") else "square"]
    model = "stick" if np.isinf(mu) else "coulomb"
    scene = jsq.Scene(mesh=square, material=jsq.Material(E=E, nu=NU, thickness=H), fingers=jsq.Fingers(radius=radius),
                      grip=grip, friction=0.5 if np.isinf(mu) else mu, friction_model=model, depth=depth, contact="point")
    res = jsq.squeeze(scene)
    # the oracle's event checks every depth / 10 (bisection locates each event to 1e-12 L)
    o = from_mesh(square, E, NU, H, radius, grip, mu, depth, contact="point", step=depth / 10)
    L = float(np.ptp(square.points, axis=0).max())
    assert res.outcome.name == o.status == outcome
    assert abs(float(res.final_depth) - o.final_depth) <= 1e-9 * L
    assert (o.final_depth < depth) == (outcome != "SUCCESS")
    _agree(res, o, L, kinds)
    # one contact per finger, nodes free to sink into the tips (no event A)
    assert np.count_nonzero(o.modes) == (1 if outcome == "LOST_CONTACT" else 2)


def test_a_sliding_point_contact_that_carries_nothing_fails_by_slip():
    """A two-point grasp holds only forces along the segment between its contacts (force and
    torque balance). Finger 1's tip (3 L across) turns and drags its stuck contact until the
    force leaves the cone (C at 0.50 mm); sliding, the contact can hold no force on its cone's
    edge, so the trial set carries nothing: every force is round-off (~1e-16 N). The grasp
    fails by slip there, as in the oracle. The peel rule judged those round-off forces by
    their own size and let both contacts go by the sign of the round-off: LOST_CONTACT, or
    SLIP_FAILURE, by chance (a finer mesh of the same triangle: C B B at 0.039 mm)."""
    mesh = jsq.shapes.polygon([(0, 0), (0.09, 0.01), (0.03, 0.07)], max_edge=0.02)     # 17 nodes
    P = np.asarray(mesh.points) + np.asarray(mesh.offset)
    grip = tuple(int(np.argmin(np.linalg.norm(P - xy, axis=1))) for xy in ((0.024375, 0.056875), (0.09, 0.01)))
    rotation = [[0.0, 0.0], [-35.24, 0.0]]
    scene = jsq.Scene(mesh=mesh, material=jsq.Material(E=E, nu=-0.9, thickness=H),
                      fingers=jsq.Fingers(radius=0.27, rotation=rotation), grip=grip, friction=0.3,
                      depth=0.0072, contact="point")
    res = jsq.squeeze(scene)
    o = from_mesh(mesh, E, -0.9, H, 0.27, grip, 0.3, 0.0072, contact="point", rotation=rotation, step=0.00072)
    assert res.outcome.name == o.status == "SLIP_FAILURE"
    L = float(np.ptp(mesh.points, axis=0).max())
    assert abs(float(res.final_depth) - o.final_depth) <= 1e-9 * L and 4e-4 < o.final_depth < 6e-4
    _agree(res, o, L, "C")
    assert np.abs(np.asarray(res.final_forces)).max() < 1e-12 * np.abs(np.asarray(res.finger_forces)).max()


def test_a_sliding_point_contact_that_pulls_fails_by_slip():
    """The same triangle, grip nodes at (30, 70) and (36, 4) mm, both tips turning (-57 and
    15 rad/m), r = 270 mm, mu = 0.5. Finger 0's contact leaves its cone at 1.99 mm (C); the
    set with it sliding pulls at both contacts (by the squeeze's largest force): a set whose
    finger slides whole is the squeeze's end, as in the oracle. The peel rule let both
    contacts go there (C B B: LOST_CONTACT); it now leaves a failing set alone: SLIP_FAILURE at
    the C, its row that set with the oracle's forces (random point-contact scenes, 2026-12-05:
    8 of 9 such scenes ended LOST_CONTACT before; docs/numerics.md §2, 24)."""
    mesh = jsq.shapes.polygon([(0, 0), (0.09, 0.01), (0.03, 0.07)], max_edge=0.02)     # 17 nodes
    P = np.asarray(mesh.points) + np.asarray(mesh.offset)
    grip = tuple(int(np.argmin(np.linalg.norm(P - xy, axis=1))) for xy in ((0.03, 0.07), (0.036, 0.004)))
    rotation = [[-56.97, 0.0], [14.98, 0.0]]
    scene = jsq.Scene(mesh=mesh, material=jsq.Material(E=E, nu=0.3, thickness=H),
                      fingers=jsq.Fingers(radius=0.27, rotation=rotation), grip=grip, friction=0.5,
                      depth=0.018, contact="point")
    res = jsq.squeeze(scene)
    o = from_mesh(mesh, E, 0.3, H, 0.27, grip, 0.5, 0.018, contact="point", rotation=rotation, step=0.0018)
    assert res.outcome.name == o.status == "SLIP_FAILURE"
    L = float(np.ptp(mesh.points, axis=0).max())
    assert abs(float(res.final_depth) - o.final_depth) <= 1e-9 * L and 1.9e-3 < o.final_depth < 2.1e-3
    _agree(res, o, L, "C")
    k = int(res.count) - 1
    on = np.asarray(res.modes[k]) > 0
    x = np.asarray(mesh.points)[mesh.boundary] + np.asarray(res.boundary_displacement[k])      # the result's frame
    rel = x[on] - np.asarray(res.centres[k])[np.asarray(res.finger[k])[on]]
    fn = np.sum(np.asarray(res.forces[k])[on] * rel, axis=1) / np.linalg.norm(rel, axis=1)
    assert fn.max() < -0.5 * np.abs(np.asarray(res.forces)).max()            # both pull: the set cannot hold


# (mu, s [m], push [m], angle, outcome, push events' kinds); grip (7, 27), r = 20 mm, depth 10 mm
PUSH = {
    "mu=0.5 push 3 mm along the normal (A; a new contact slides: C)":
        (0.5, 0.0513, 0.003, 0.0, "SUCCESS", "AAAAAAAA" + "ACA"),
    "mu=0.15 oblique push (A, C, D; SLIP_FAILURE at 2.26 mm)":
        (0.15, 0.0513, 0.003, 0.5, "SLIP_FAILURE", "AACAACCCAAADDADDA" + "CCCCCC"),
}


@pytest.mark.parametrize("name", list(PUSH))
def test_adversary_push_matches_the_oracle(meshes, name):
    mu, s, push, angle, outcome, kinds = PUSH[name]
    square = meshes["square"]
    grip, radius, depth = (7, 27), 0.02, 0.01
    adv = dict(s=s, push=push, angle=angle)
    scene = jsq.Scene(mesh=square, material=jsq.Material(E=E, nu=NU, thickness=H), fingers=jsq.Fingers(radius=radius),
                      grip=grip, friction=mu, depth=depth, adversary=jsq.Adversary(**adv))
    res = jsq.squeeze(scene)
    # squeeze phase checked every depth / 10; the push at the library's default step (push / 50:
    # the qualities are trapezoid sums over the recorded rows)
    o = from_mesh(square, E, NU, H, radius, grip, mu, depth, adversary=adv, step=depth / 10)
    L = float(np.ptp(square.points, axis=0).max())
    assert res.outcome.name == o.status == outcome
    assert jsq.Status(int(res.squeeze_status)).name == o.squeeze_status == "SUCCESS"
    assert abs(float(res.final_depth) - depth) <= 1e-12
    assert abs(float(quality.failure_push(res)) - o.failure_push) <= 1e-9 * L
    assert (o.failure_push < push) == (outcome != "SUCCESS")
    np.testing.assert_allclose(np.asarray(res.centres[0])[2], o.pusher_start, rtol=0, atol=1e-9 * L)
    _agree(res, o, L, kinds)
    W = o.adversary_work
    assert abs(float(quality.adversary_work(res)) - W) <= 1e-6 * abs(W)
    np.testing.assert_allclose(np.asarray(quality.finger_work(res)), o.finger_work, rtol=0, atol=1e-6 * abs(W))
    np.testing.assert_allclose(np.asarray(res.push_work), [W, *o.finger_work], rtol=0, atol=1e-6 * abs(W))


# ----------------------------------------------------------------------------- contacts that pull
# Rectangle 80 x 50 mm (8 mm edges, 46 boundary nodes) and a hexagon 80 mm across (7 mm edges, 36 boundary
# nodes), nu = -0.9. (grip, mu, radius [m], depth [m], rotation, outcome, the event (kind, node) pair that
# must appear at one depth, in this order)
PULLING = {
    # node 23 re-touches finger 0 at 6.105 mm, where sticking would pull it: it slides (A, C at
    # one depth); the engine once let it go (B), left it inside the tip and stopped, STALLED
    "a new contact whose stick force pulls slides": ((23, 30), 3.0, 0.08, 0.012, None, "SUCCESS", ("A", 23, "C", 23)),
    "the same with turning tips": ((21, 1), 1.0, 0.24, 0.0064, [[0.0, -16.43, -0.14], [0.0, 16.69, 0.17]],
                                   "SLIP_FAILURE", ("A", 21, "C", 21)),
    # the tips turn away from a grip inside both cones (margin 0.11 rad): both grip contacts pull
    # at the touch and let go, no finger holds the object (once read as STALLED)
    "a grip the turning tips leave at the touch": ((4, 18), 1.0, 0.08, 0.0024, [[0.0, 28.21, -0.17], [0.0, 6.63, -0.31]],
                                                  "LOST_CONTACT", ("B", 18, "B", 4)),
    # node 15 re-touches at 6.80 mm pulling; the edge its stick force points to pulls too (fn
    # -4.7e-7 N at the probe), the other pushes (+7.3e-7 N): it takes that one (it stalled)
    "hexagon: a pulling contact takes the other edge": ((14, 23), 3.0, 0.16, 0.012, None, "SUCCESS",
                                                        ("A", 15, "C", 15)),
}


@pytest.fixture(scope="module")
def pulling_meshes():
    hexagon = [(0.04, 0), (0.02, 0.035), (-0.02, 0.035), (-0.04, 0), (-0.02, -0.035), (0.02, -0.035)]
    return {"rectangle": jsq.shapes.rectangle(0.08, 0.05, max_edge=0.008),
            "hexagon": jsq.shapes.polygon(hexagon, max_edge=0.007)}


@pytest.mark.parametrize("name", list(PULLING))
def test_contacts_that_pull_match_the_oracle(pulling_meshes, name):
    grip, mu, radius, depth, rot, outcome, pair = PULLING[name]
    mesh = pulling_meshes["hexagon" if name.startswith("hexagon") else "rectangle"]
    scene, res, o, L = _turning(mesh, -0.9, radius, grip, mu, depth, rot)
    assert res.outcome.name == o.status == outcome
    assert abs(float(res.final_depth) - o.final_depth) <= 1e-9 * L
    _agree(res, o, L, set("".join(e.kind for e in o.events)))
    assert sliding_against_friction(res).size == 0
    if outcome == "LOST_CONTACT":       # let go at the touch: no deformation, no rigid motion (it read NaN)
        assert np.all(np.asarray(res.boundary_displacement) == 0) and np.all(np.asarray(res.displacement) == 0)
        assert np.all(np.asarray(res.rigid) == 0)
        from jaxsqueeze.post import views
        assert [e["relative_depth"] for e in views.summary(res, scene)["events"]] == [0.0, 0.0]
    rows = res.events.rows()
    at = [i for i, (d, n, k, f) in enumerate(rows) if (k, n) == pair[:2]]
    assert any(i + 1 < len(rows) and rows[i + 1][2:0:-1] == pair[2:] and abs(rows[i + 1][0] - rows[i][0]) <= 1e-9 * L
               for i in at), rows


# ----------------------------------------------------------------------------- forces through the cone's apex
# Rectangle of PULLING, mu = 3, r = 80 mm, depth 12 mm, turning tips: the tips turn until the two
# grip forces fall through zero together, the force along the grip segment inside both cones but
# nearer the edge than the axis (where the cone margin is below the normal force). Both
# contacts release (B); the engine once logged the margin's crossing instead (C, then B, or a
# stall), and with point contacts went NONFINITE. (grip, rotation, contact, the B depth [mm])
APEX = {
    "stick-slip history, then both let go": ((15, 28), [[0.0, 36.578688125151245, -0.006019036384644127],
                                                         [0.0, -49.949955613376616, -0.09416984159005433]],
                                             "segment", 11.341517),
    "the grip alone lets go": ((17, 0), [[0.0, -12.670166399366485, -0.12673960046614352],
                                         [0.0, 38.55884412192954, -0.1266138729205547]], "segment", 8.58201),
    "point contacts let go": ((15, 28), [[0.0, 36.578688125151245, -0.006019036384644127],
                                         [0.0, -49.949955613376616, -0.09416984159005433]], "point", 7.205887),
}


@pytest.mark.parametrize("name", list(APEX))
def test_forces_through_the_cone_apex_release(pulling_meshes, name):
    grip, rot, contact, d_mm = APEX[name]
    mesh, nu, mu, radius, depth = pulling_meshes["rectangle"], -0.9, 3.0, 0.08, 0.012
    _, res, o, L = _turning(mesh, nu, radius, grip, mu, depth, rot, contact=contact,
                            step=depth / 10 if contact == "point" else None)
    assert res.outcome.name == o.status == "LOST_CONTACT"
    assert abs(float(res.final_depth) - o.final_depth) <= 1e-9 * L and abs(o.final_depth - d_mm * 1e-3) <= 1e-8
    _agree(res, o, L, set("".join(e.kind for e in o.events)))
    last = [(k, f) for d, n, k, f in res.events.rows() if abs(d - o.final_depth) <= 1e-9 * L]
    assert sorted(last) == [("B", 0), ("B", 1)]
    assert np.all(np.asarray(res.modes[-1]) == 0) and np.all(np.isfinite(np.asarray(res.final_forces)))


# ----------------------------------------------------------------------------- full stick: a node that sinks
# A quadrilateral 90 x 70 mm with a triangular hole (8 mm edges, 49 boundary nodes), nu = -0.9, full stick
# (one compiled program: both rotations have shape (2, 2)). (grip, radius [m], depth [m], rotation, outcome,
# the events at the release depth)
SUNK = {
    # B of node 6 at 5.42 mm drops its shear and leaves node 4 inside tip 0: it joins there (A at
    # the same depth) and the squeeze goes on to its depth (it stopped with STALLED). At 11.59 mm
    # a release starts a cascade of 26 events at one depth, which took more CHECK passes than
    # there were (SETTLE_ITERS was 6): the row was accepted with node 3 pulling 1.3 N, SUCCESS
    "a released neighbour's sunk node joins": ((6, 14), 0.09, 0.0135, [[0.0, 0.0], [0.0, 0.0]], "SUCCESS",
                                               [("B", 6), ("A", 4)]),
    # tip 1 turns until both its contacts let go, a node left inside it: LOST_CONTACT (it read STALLED)
    "a finger that lets go of everything": ((31, 23), 0.0135, 0.0036, [[0.0, 0.0], [-67.59, -0.05]], "LOST_CONTACT",
                                            [("B", 22), ("B", 23)]),
}


@pytest.fixture(scope="module")
def holed_quad():
    with pytest.warns(UserWarning, match=r"two elements thick"):            # coarse on purpose
        return jsq.shapes.polygon([(-0.04, -0.03), (0.04, -0.03), (0.05, 0.03), (-0.03, 0.04)],
                                  holes=[[(-0.01, -0.01), (0.015, -0.005), (0.005, 0.015)]], max_edge=0.008)


@pytest.mark.parametrize("name", list(SUNK))
def test_full_stick_nodes_left_inside_a_tip_match_the_oracle(holed_quad, name):
    grip, radius, depth, rot, outcome, at = SUNK[name]
    mesh, nu = holed_quad, -0.9
    _, res, o, L = _turning(mesh, nu, radius, grip, None, depth, rot, model="stick")
    assert res.outcome.name == o.status == outcome
    assert abs(float(res.final_depth) - o.final_depth) <= 1e-9 * L
    _agree(res, o, L, set("".join(e.kind for e in o.events)))
    rows = res.events.rows()
    i = [(k, n) for d, n, k, f in rows].index(at[0])
    assert sorted((k, n) for d, n, k, f in rows if abs(d - rows[i][0]) <= 1e-9 * L) == sorted(at)
    if outcome == "SUCCESS":       # every row: compressive, on the tips, no free node inside one
        check_states(res, mesh, 0.5, "stick")
        P = np.asarray(mesh.points)[np.asarray(mesh.boundary)]
        for r in range(int(res.count)):
            x = P + np.asarray(res.boundary_displacement[r])
            gap = np.linalg.norm(x[:, None] - np.asarray(res.centres[r])[None], axis=-1).min(1) - radius
            assert np.all(gap[np.asarray(res.modes[r]) == 0] > -10 * 1e-9 * L), r


def test_a_contact_a_cascade_leaves_pulling_lets_go_at_its_depth():
    """Full stick on a rectangle 80 x 50 mm (5 mm edges), nu = 0.49, r = 40 mm, grip nodes 29
    and 44, tips not turning. At 9.528 mm node 28 lets go and finger 0's contact rolls from
    nodes 27-28 to 29-30 in eight events at one depth; the set they leave has node 46 on finger
    1 pulling (2 % of the largest force): it lets go there (B) and touches again at 9.737 mm (A).
    The oracle tested its events only at its next step's end, where 46 pushed again, and kept
    it (end forces 1.5e-3 apart); it now lets such a contact go at the depth, as the engine's
    peel rule does (random full-stick scene, 2026-12-05)."""
    mesh = jsq.shapes.rectangle(0.08, 0.05, max_edge=0.005)
    _, res, o, L = _turning(mesh, 0.49, 0.04, (29, 44), None, 0.012, None, model="stick")
    assert res.outcome.name == o.status == "SUCCESS"
    _agree(res, o, L, "AAAABAAAAABBBBBAA")     # one depth's events sorted by kind
    rows = res.events.rows()
    d0 = [d for d, n, k, f in rows if (k, n) == ("B", 28)][0]
    assert abs(d0 - 9.528203e-3) <= 1e-9
    cascade = [(k, n, f) for d, n, k, f in rows if abs(d - d0) <= 1e-9 * L]
    assert len(cascade) == 9 and cascade[-1] == ("B", 46, 1)
    after = [(k, n, round(d * 1e3, 3)) for d, n, k, f in rows if d > d0 + 1e-9 * L]
    assert after[0] == ("A", 46, 9.737)
    check_states(res, mesh, 0.5, "stick")


def test_a_grip_node_that_peels_off_in_shrinking_cycles_is_followed_to_its_end():
    """Full stick on the rectangle 80 x 50 mm (5 mm edges), nu = -0.9, r = 240 mm, grip nodes 27
    and 51, tips not turning. Grip node 27 pulls at 1.2536 mm and lets go (B); released, it lies
    inside its tip (the release dropped its shear) and joins again where it is (A), pushing,
    until it pulls again: at 1.2836, 1.0 µm deeper, 34 nm deeper, and at 1.284678 mm released
    it no longer sinks and the tips go on to 3.2 mm. The engine judged a contact made at the
    event depth d* by its force at d* + η (η = step / 100 = 0.64 µm here), beyond the 34 nm
    cycle's end: it pulled at once, let go, sank and joined again at one depth, STALLED at
    1.2846 mm. It now judges it at d* + event_tol (the event location's error, 6.4 nm), where
    this contact pushes. The oracle joined a sunk node only at its next step's end, where node 27
    was out again; it now joins one sunk by more than 10 gap_tol at the event depth, as the
    engine does, and both follow the cycles event for event (random full-stick scene, 2026-12-05)."""
    mesh = jsq.shapes.rectangle(0.08, 0.05, max_edge=0.005)
    _, res, o, L = _turning(mesh, -0.9, 0.24, (27, 51), None, 0.0032, None, model="stick")
    assert res.outcome.name == o.status == "SUCCESS"
    _agree(res, o, L, "AAABBAABABBA")     # one depth's events sorted by kind
    cycles = [round(d * 1e3, 6) for d, n, k, f in res.events.rows() if (n, k) == (27, "B")]
    assert cycles == [1.253009, 1.283629, 1.284644, 1.284678]
    check_states(res, mesh, 0.5, "stick")


def test_a_node_that_sank_is_judged_where_it_joined():
    """The same rectangle, nu = -0.9, r = 80 mm, grip nodes 14 and 21. Grip node 21 peels off in
    cycles (1.048 to 1.118 mm), and again from 2.75 mm with nodes 21 and 22 in turn. At 2.7519 mm
    node 21, released, sank 12.6 gap_tol into its tip and joined there pushing (4.9e-8 scaled),
    to pull again 7.7e-8 deeper, within event_tol (1.6e-7 scaled): judged at d* + event_tol, as a
    contact made by an A event is (its force at d* is the location's round-off), it pulled, was
    released, sank, and joined again for 16 passes at one depth: STALLED. A node that joins
    because it sank has a force of its own at d*, and is judged there; its B is the next
    bracket's. The squeeze follows the cycles, 88 events, event for event with the oracle
    (located to 1e-12 L), to 6.4 mm at the default event_tol (it needed 1e-10 m before)."""
    mesh = jsq.shapes.rectangle(0.08, 0.05, max_edge=0.005)
    _, res, o, L = _turning(mesh, -0.9, 0.08, (14, 21), None, 0.0064, None, model="stick")
    assert res.outcome.name == o.status == "SUCCESS" and len(o.events) == 88
    assert int(res.stats.refined) == 0
    _agree(res, o, L, {"A", "B"})
    check_states(res, mesh, 0.5, "stick")


def test_cycles_shorter_than_event_tol_are_followed_to_their_end():
    """Full stick on the L-shape (80 x 70 mm, 30 and 35 mm arms, 5 mm edges), nu = -0.9,
    r = 80 mm, grip nodes 18 and 2, tips turning (random full-stick scene, 2026-12-05). Node 18
    peels off in cycles that shrink from 25 µm to 4 nm (0.787 to 0.8139 mm), and node 1 from
    101 µm to 19 nm later. At the default event_tol (step / 10,000, 24 nm) the cycle at 0.8125 mm
    read as an event undone within event_tol of the last row, and the squeeze stopped there,
    STALLED; then it was resolved again with event_tol / 10, twice (docs/numerics.md §2, 22).
    That row was a step that stopped just short of the cycle's B: measured from the last event's
    row, no cycle here undoes itself (§2, 25), no refinement is needed, and the squeeze reaches
    12 mm, 44 events, event for event with the oracle."""
    mesh = jsq.shapes.polygon([(0, 0), (0.08, 0), (0.08, 0.03), (0.035, 0.03), (0.035, 0.07), (0, 0.07)],
                              max_edge=0.005)
    rot = [[0.0, 15.63, 0.18], [0.0, -12.84, -0.35]]
    _, res, o, L = _turning(mesh, -0.9, 0.08, (18, 2), None, 0.012, rot, model="stick")
    assert res.outcome.name == o.status == "SUCCESS" and len(o.events) == 44
    assert int(res.stats.refined) == 0
    _agree(res, o, L, {"A", "B"})
    cycles = [round(d * 1e3, 4) for d, n, k, f in res.events.rows() if (n, k) == (18, "B")]
    assert cycles == [0.7874, 0.8125, 0.8139, 0.8139, 0.8139]
    check_states(res, mesh, 0.5, "stick")


def test_a_cycle_step_right_after_a_short_step_is_no_undone_event():
    """Full stick on an annulus (40/25 mm, 5 mm edges) bent by a smooth warp, nu = 0.3,
    r = 100 mm, grip nodes 17 and 11, tips turning. Node 17 peels off in cycles that halve
    (75 µm down to 8 nm at 9.90-10.05 mm, and so at other depths): released, it sinks into its tip,
    rejoins (A) and pulls again a cycle later (B). A step predicted to the next B can stop just
    short of it; the B then lay within event_tol of that row, and the undone-event test
    (measured from the last row) took the cycle for one that undid itself at one depth:
    refined six times, then STALLED at 10.03 mm. It is measured from the last event's row now:
    the squeeze follows every cycle to 15 mm, 281 events, event for event with the oracle. One
    cycle at 4.15 mm is shorter than event_tol (19 against 30 nm after the row of its last
    event): it is resolved again with event_tol / 10, once (``stats.refined``). 281 events
    overflow the default event log of 256: the eager squeeze grows it (``Settings.max_events =
    None``) and squeezes again."""
    base = jsq.shapes.annulus(0.04, 0.025, max_edge=0.005)
    P = np.asarray(base.points, dtype=float).copy()
    L = float(np.ptp(P, axis=0).max())
    c = P.mean(0)
    P = P + 0.5 * (P - c) * np.linalg.norm(P - c, axis=1, keepdims=True) / L        # radial grading
    P[:, 1] += 0.4 * (P[:, 0] - c[0]) ** 2 / L                                       # and a bend
    mesh = jsq.Mesh.from_arrays(P, np.asarray(base.triangles))
    rot = [[0.0, 2.88, 0.39], [0.0, -27.4, 0.14]]
    scene = jsq.Scene(mesh=mesh, material=jsq.Material(E=E, nu=0.3, thickness=H), friction_model="stick",
                      fingers=jsq.Fingers(radius=0.09996, rotation=rot), grip=(17, 11), friction=0.5,
                      depth=0.01499)
    res = jsq.squeeze(scene)
    o = from_mesh(mesh, E, 0.3, H, 0.09996, (17, 11), np.inf, 0.01499, model="stick", rotation=rot)
    assert res.outcome.name == o.status == "SUCCESS" and len(o.events) == 281 > scene.settings.bounds()[1]
    assert int(res.stats.refined) == 1
    _agree(res, o, float(np.ptp(mesh.points, axis=0).max()), {"A", "B"})
    check_states(res, mesh, 0.5, "stick")


def test_a_rejected_contact_set_arms_no_sliding_node(pulling_meshes):
    """Node 28 slides with an inconsistent rate (a jam, unarmed) when node 3 joins at 2.029 mm
    and slides (A, C). The engine's first pass solves the set with node 3 sticking, where 28's
    rate is consistent; that set is rejected, yet it armed 28, whose rate in the set that holds
    is -5.6, so 28 stuck (D) and slid again 1e-8 L deeper (C), and the squeezes parted from
    there (SUCCESS). Only a set that holds arms a node now, as in the oracle (rectangle of
    PULLING, nu = 0.49, mu = 3, r = 160 mm, turning tips)."""
    mesh, nu, mu, radius, depth, grip = pulling_meshes["rectangle"], 0.49, 3.0, 0.16, 0.0025, (7, 29)
    rot = [[-1712.8, -8.11, 0.0], [-4480.3, -4.04, 0.0]]
    _, res, o, L = _turning(mesh, nu, radius, grip, mu, depth, rot)
    assert res.outcome.name == o.status == "SLIP_FAILURE"       # C 27 at 2.284 mm: finger 1 slides
    assert abs(float(res.final_depth) - o.final_depth) <= 1e-9 * L
    _agree(res, o, L, "AACCBBAAACACC")
    at = [(k, n) for d, n, k, f in res.events.rows() if abs(d - 0.0020288108) <= 1e-9]
    assert at == [("A", 3), ("C", 3)]


def test_a_cone_margin_that_dips_below_zero_within_a_step_is_found(pulling_meshes):
    """The same squeeze to 12 mm: node 27's cone margin falls below zero at 2.284 mm and turns
    back up by 2.33 mm, inside one default step (12 mm / 50). Its ends and another node's
    crossing at the step's end showed no C there, so finger 1 went on and the outcome depended
    on the target depth and the step (SUCCESS to 12 mm, SLIP_FAILURE at 2.284 mm to 2.5 mm).
    The dip is found from the values and rates at the step's ends (``engine._dip``): every
    step from 0.05 to 0.24 mm fails there, as the oracle does at 0.05 mm steps."""
    mesh, nu, mu, radius, grip = pulling_meshes["rectangle"], 0.49, 3.0, 0.16, (7, 29)
    rot = [[-1712.8, -8.11, 0.0], [-4480.3, -4.04, 0.0]]
    scene = jsq.Scene(mesh=mesh, material=jsq.Material(E=E, nu=nu, thickness=H),
                      fingers=jsq.Fingers(radius=radius, rotation=rot), grip=grip, friction=mu, depth=0.012)
    o = from_mesh(mesh, E, nu, H, radius, grip, mu, 0.012, rotation=rot, step=5e-5)
    L = float(np.ptp(mesh.points, axis=0).max())
    for step in (None, 2e-4):
        res = jsq.squeeze(scene.replace(settings=jsq.Settings(step=step)))
        assert res.outcome.name == o.status == "SLIP_FAILURE"
        assert abs(float(res.final_depth) - o.final_depth) <= 1e-9 * L
        _agree(res, o, L, "AACCBBAAACACC")
        assert res.events.rows()[-1][1:3] == (27, "C")
