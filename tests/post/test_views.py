"""Views rebuild rows from what the engine recorded (issue 9: the rigid part g of every row is in
the result, so no view refits it)."""
import numpy as np

import jaxsqueeze as jsq
from jaxsqueeze.post import views
from physics import nearest, symmetric_square


def test_row_displacement_uses_the_recorded_rigid_part():
    """The full field rebuilt at the final row equals the engine's own final field, on an
    off-centre grip (a real rigid rotation)."""
    mesh = symmetric_square(0.1, 0.01)
    scene = jsq.Scene(mesh=mesh, material=jsq.Material(E=1e5, nu=0.3, thickness=0.0254),
                      fingers=jsq.Fingers(radius=0.01), grip=(nearest(mesh, (-0.01, -0.05)), nearest(mesh, (0.01, 0.05))),
                      friction=0.5, depth=0.01)
    op = scene.operator()
    res = jsq.squeeze(scene, op, throw=True)
    assert abs(float(res.rigid[-1][2])) > 1e-4                 # the object turned
    u = views.row_displacement(res, op, -1)
    ref = np.asarray(res.displacement)
    np.testing.assert_allclose(u, ref, rtol=0, atol=1e-10 * np.abs(ref).max())
    # an earlier row: its boundary part is the recorded boundary displacement
    k = len(res.depth) // 2
    uk = views.row_displacement(res, op, k)
    bd = np.asarray(res.boundary_displacement[k])
    np.testing.assert_allclose(uk[np.asarray(res.nodes)], bd, rtol=0, atol=1e-10 * np.abs(bd).max())
