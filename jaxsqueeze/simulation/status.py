"""Outcome codes carried as values in jitted results (DESIGN 2.4)."""
from __future__ import annotations

import enum


class Status(enum.IntEnum):
    """Status of a squeeze. Stored as an int32 in results so ``vmap`` keeps working."""

    SUCCESS = 0          #: target depth reached
    SLIP_FAILURE = 1     #: every contact on one finger slides
    MAX_STEPS = 2        #: step bound reached before the target depth
    NEWTON_FAILURE = 3   #: slip-angle Newton solve did not converge
    OVERFLOW = 4         #: more contact (or sliding) nodes than slots (raise ``capacity`` / ``sliding_capacity``)
    NONFINITE = 5        #: a NaN or inf appeared in the state
    EVENT_OVERFLOW = 6   #: the event log is full (raise ``max_events``)
    INFEASIBLE_GRIP = 7  #: the segment between the initial contacts leaves a friction cone, or a placed fingertip (pusher) cannot touch
    STALLED = 8          #: no consistent contact set at this depth (an event undid itself, or a frictionless object would slide away)
    LOST_CONTACT = 9     #: a grasping finger lost all of its contacts (the object fell out)
    INVALID_INPUT = 10   #: a number of the scene or its settings is invalid (see ``result.invalid``)

    def __str__(self) -> str:
        return self.name

    @property
    def advice(self) -> str:
        return _ADVICE[self]


_ADVICE = {
    Status.SUCCESS: "The squeeze reached the target depth.",
    Status.SLIP_FAILURE: "The grasp failed: all contacts on one finger slide. Try more friction or another grip.",
    Status.LOST_CONTACT: ("The grasp failed: one finger lost all of its contacts (every contact broke, event B). "
                          "Try another grip or a smaller depth."),
    Status.INVALID_INPUT: ("An input number is invalid (NaN, infinite, out of range or inconsistent); "
                           "result.invalid names it. Fix that field of the scene or its settings."),
    Status.MAX_STEPS: "Step bound reached. Raise Settings.max_steps or the step size.",
    Status.NEWTON_FAILURE: ("Slip-angle Newton did not converge. Lower Settings.step or raise Settings.newton_iters; "
                            "for a frictionless squeeze try another step size or a small Coulomb friction "
                            "(docs/numerics.md, 5.1)."),
    Status.OVERFLOW: "More contact nodes than slots, or more sliding nodes than Newton slots. Raise Settings.capacity or Settings.sliding_capacity (or leave both at None: an eager squeeze then grows them).",
    Status.NONFINITE: ("A non-finite value appeared: a configuration solve was singular or overflowed. Check the "
                       "grip (two contacts that cannot hold the object, e.g. both on one straight edge), the "
                       "fingertip rotation (too fast), and the scene's scale and material values (units, and E "
                       "within the precision: float32 overflows near 1e38)."),
    Status.EVENT_OVERFLOW: "The event log is full. Raise Settings.max_events.",
    Status.STALLED: ("No consistent contact set exists at this depth: a node touched a fingertip but as a contact "
                     "it would pull, or a released contact would land inside its fingertip (full stick with "
                     "turning fingertips: use Coulomb friction, or a finer Settings(event_tol) where a node "
                     "peels off in ever shorter cycles; the squeeze already retried with event_tol down to "
                     "1e-6 of it, result.stats.refined), or (frictionless) holding the object in place "
                     "would take more than 1 % tangential force, i.e. the object would slide out sideways (an "
                     "asymmetric frictionless grip). Grip nearer a symmetry line, refine the mesh near the "
                     "contact, or use Coulomb friction."),
    Status.INFEASIBLE_GRIP: ("The segment between the two grip nodes leaves a friction cone, so the squeeze "
                             "cannot start (Section I-A), or a placed fingertip (or the adversary's pusher, "
                             "when result.squeeze_status is SUCCESS) cannot touch the object from outside where "
                             "it was placed (frictionless: or, re-centred on the line through its two first "
                             "contacts, would reach into the object). Pick nodes more nearly opposite, raise the friction, or place the "
                             "fingertip (pusher) elsewhere or more nearly along the inward normal. A placed "
                             "fingertip centred between two boundary nodes first touches one of them off its axis "
                             "and is judged by its own normal there, tilted by about asin(offset / radius): where "
                             "the node spacing is not small against the radius, refine the mesh near the "
                             "placement (shapes: refine_near) or centre the fingertip on a node "
                             "(Placement(s=scene.arc_length(grip)))."),
}
