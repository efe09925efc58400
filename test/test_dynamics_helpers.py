"""Hand-built models for the dynamics tests (closed forms need small, known models)."""

import numpy as np

from panel_deploy.dynamics import kernels
from panel_deploy.dynamics.panel_contact import near_pairs
from panel_deploy.model import Body, ClosureParameters, Hinge, Model, box_inertia

A, B, T, MASS = 0.1, 0.1, 0.005, 0.02
SIZE = np.array([A, B, T])


def panel(name, x, y, mass=MASS):
    return Body(name, (), SIZE.copy(), mass, box_inertia(mass, SIZE), np.array([x, y, 0.0]))


def hinge(name, a, b, point, axis, k=0.1, c=0.0043, theta_stowed=np.pi, length=B, springs=1):
    axis = np.asarray(axis, float)
    return Hinge(name, a, b, np.asarray(point, float), axis / np.linalg.norm(axis), length,
                 "top", k, c, theta_stowed, (), springs)


def plate_on_hinge(k=0.1, c=0.0043, gravity=(0.0, 0.0, 0.0), k_s=1000.0, c_s=0.5, springs=1):
    """Ground panel and one panel hinged on their shared edge x = A/2, top facet,
    by ``springs`` spring-loaded hinges in parallel (k, c each)."""
    bodies = [panel("G", 0.0, 0.0), panel("P", A, 0.0)]
    hinges = [hinge("h", 0, 1, (A / 2, B / 2, T / 2), (0, -1, 0), k, c, springs=springs)]
    return Model.build(bodies, hinges, 0, k_s=k_s, c_s=c_s, gravity=gravity)


def hinge_inertia(model):
    """The plate's moment of inertia about its hinge axis, kg m^2."""
    h, body = model.hinges[0], model.bodies[1]
    r0 = body.flat_position - h.point
    return h.axis @ (body.inertia + body.mass * (r0 @ r0 * np.eye(3) - np.outer(r0, r0))) @ h.axis


def overdamped_plate(root=5e3):
    """The plate on a linear spring and damper whose roots are ~-root and -10 1/s,
    and the closed form of theta from theta(0) = 1 at rest, a function of t."""
    I_h = hinge_inertia(plate_on_hinge())
    c = root * I_h
    model = plate_on_hinge(k=10.0 * c, c=c)
    lam = np.roots([I_h, c, 10.0 * c])
    a = np.linalg.solve([[1, 1], lam], [1.0, 0.0])
    return model, lam, lambda t: np.exp(np.outer(t, lam)) @ a


def random_branched(seed=0, closure="penalty", gravity=(0.3, -9.81, 1.0)):
    """Six bodies with random geometry and inertia: a branched tree plus one loop."""
    rng = np.random.default_rng(seed)
    bodies = []
    for i in range(6):
        m = rng.uniform(0.01, 0.05)
        X = rng.normal(size=(3, 3))
        inertia = 1e-5 * (X @ X.T + np.eye(3))
        bodies.append(Body(f"b{i}", (), SIZE.copy(), m, inertia, rng.uniform(-0.2, 0.2, 3)))
    edges = [(0, 1), (1, 2), (1, 3), (0, 4), (4, 5), (2, 5)]
    # every other hinge, the cut one (2-5) among them, has two springs in parallel
    hinges = [hinge(f"h{a}{b}", a, b, rng.uniform(-0.2, 0.2, 3), rng.normal(size=3),
                    k=rng.uniform(0.05, 0.2), c=rng.uniform(0.001, 0.01), springs=1 + i % 2)
              for i, (a, b) in enumerate(edges)]
    cl = ClosureParameters(closure, 1e4, 30.0, 2e4, 20.0, 1e-3, 1e-10)
    return Model.build(bodies, hinges, 0, k_s=500.0, c_s=0.3, closure=cl, gravity=gravity)


def ring_2x2(closure="penalty", k_M=1e6, c_M=280.0, baumgarte=1e-3, k_h=(0.1, 0.05)):
    """Four unit panels in a ring (cells (1,1), (1,2), (2,2), (2,1)), all hinges on the
    top facet, ground (1,1); the hinge (2,1)-(2,2) is cut. The two horizontal hinges have
    different stiffness k_h so the loop carries a force at the cut."""
    bodies = [panel("11", -A / 2, B / 2), panel("12", A / 2, B / 2),
              panel("22", A / 2, -B / 2), panel("21", -A / 2, -B / 2)]
    top = T / 2
    hinges = [
        hinge("v1", 0, 1, (0, B, top), (0, -1, 0), theta_stowed=0.0),
        hinge("h2", 1, 2, (0, 0, top), (1, 0, 0), k=k_h[1]),
        hinge("v2", 3, 2, (0, 0, top), (0, -1, 0), theta_stowed=0.0),
        hinge("h1", 0, 3, (-A, 0, top), (1, 0, 0), k=k_h[0]),
    ]
    cl = ClosureParameters(closure, k_M, c_M, k_M, c_M, baumgarte, 1e-10)
    return Model.build(bodies, hinges, 0, cut_hinges=[2], k_s=1000.0, c_s=0.5, closure=cl)


def near(P):
    """A new candidate list of the panel contact pairs of ``P`` (panel_contact.near_pairs),
    what a run passes the kernels."""
    return near_pairs(P)


def scratch(P):
    """A new scratch of a run on ``P`` (kernels.scratch: the candidate list
    and the right-hand side's arrays), what a run passes the right-hand side."""
    return kernels.scratch(P)


def paper_hinge_law(theta, omega, k, c, k_s, c_s):
    """Eq. (2)-(4) with the contact in parallel with the hinge spring."""
    tau, energy = -k * theta - c * omega, 0.5 * k * theta**2
    for over in (theta - np.pi if theta > np.pi else 0.0, theta if theta < 0 else 0.0):
        if over:
            tau += -k_s * over - c_s * omega
            energy += 0.5 * k_s * over**2
    return tau, energy
