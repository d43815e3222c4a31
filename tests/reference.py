"""Independent references for the tests: plain NumPy, written apart from the package's kernels."""

import numpy as np


def neo_hooke_psi(F, mu, kappa):
    J = np.linalg.det(F)
    return 0.5 * mu * (J ** (-2 / 3) * np.trace(F.T @ F) - 3) + 0.25 * kappa * (J**2 - 1 - 2 * np.log(J))


def neo_hooke_piola(F, mu, kappa):
    J = np.linalg.det(F)
    FinvT = np.linalg.inv(F).T
    I1 = np.trace(F.T @ F)
    return mu * J ** (-2 / 3) * (F - I1 / 3 * FinvT) + 0.5 * kappa * (J**2 - 1) * FinvT


def surface_nodal_forces(vertices, faces, P):
    """f_v = sum over faces at v of (A_f / 3) P N_f: the traction P N integrated with linear shapes."""
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    an = 0.5 * np.cross(b - a, c - a)
    f = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(f, faces[:, k], an @ P.T / 3.0)
    return f


def random_rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q
