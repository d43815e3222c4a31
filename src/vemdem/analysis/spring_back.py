"""What a pack gives back when its load comes off: the grains' deformation, the contact layer's
gaps, and the grains' rearrangement (docs/results.md, "What the spring-back is made of").

Every grain's motion is split into its best rigid fit to its stress-free reference (Kabsch: the
rotation R and the vertex centroid t minimising sum |x - t - R (X - Xbar)|^2) and the rest,
u = x - t - R (X - Xbar), its deformation. At a contact record between grains A and B, with
contact points p_A, p_B at the record's material points (ContactModel.grain_contacts) and the gap
vector g = p_A - p_B, the branch vector between the grains' centroids is exactly

    l = t_B - t_A = R_A (X_A - Xbar_A) - R_B (X_B - Xbar_B) + (u_A(p_A) - u_B(p_B)) - g.

From a state 0 to a state 1, keeping the records' material points of state 0, the change of l is
the sum of four parts: the grains' deformation at the contact, the gap's change along the normal
n = g0 / |g0| (the contact layer), its change across the normal (the contact's material points
sliding or rolling apart) and the rigid rotations. The best-fit strain of the branch vectors
(Liao et al., 1997), E = [sum_c dl_c (x) l_c][sum_c l_c (x) l_c]^-1, is linear in dl, so it splits
exactly into the same four parts. The tangential and rotation parts together are the grains'
rearrangement; apart, a grain rolling without sliding shows in both, with opposite signs (its
contact's material points part across the normal as it turns).
"""

from __future__ import annotations

import numpy as np

PARTS = ("deformation", "contact_gap", "tangential", "rotation")


def spring_back_shares(back: dict) -> dict[str, float] | None:
    """The shares of a spring_back record (lid_compression's summary.json) in its branch strain: the
    grains' deformation, the contact layer's gaps and the rest, rearrangement (tangential + rotation:
    the split is exact); None where the pack gave nothing back or the record is an error."""
    total = back.get("branch_strain")
    if not isinstance(total, float) or not total > 0.0:
        return None
    shares = {k: back[k] / total for k in ("deformation", "contact_gap")}
    shares["rearrangement"] = 1.0 - shares["deformation"] - shares["contact_gap"]
    return shares


def rigid_fits(reference: np.ndarray, x: np.ndarray, vertex_ptr: np.ndarray):
    """(t (G, 3), R (G, 3, 3), u (N, 3)): every grain's vertex centroid, the rotation of its best
    rigid fit to its reference vertices, and what that fit leaves at each vertex."""
    starts = vertex_ptr[:-1]
    counts = np.diff(vertex_ptr)
    grain = np.repeat(np.arange(len(counts)), counts)
    X = reference - (np.add.reduceat(reference, starts) / counts[:, None])[grain]
    t = np.add.reduceat(x, starts) / counts[:, None]
    xc = x - t[grain]
    U, _, Vt = np.linalg.svd(np.add.reduceat(X[:, :, None] * xc[:, None, :], starts))
    V, Ut = np.transpose(Vt, (0, 2, 1)), np.transpose(U, (0, 2, 1))
    flip = np.ones((len(counts), 3))
    flip[:, 2] = np.sign(np.linalg.det(V @ Ut))  # a rotation, never a reflection
    R = (V * flip[:, None, :]) @ Ut
    return t, R, xc - np.einsum("vij,vj->vi", R[grain], X)


def branch_strain_split(reference, vertex_ptr, x0, x1, grain_a, grain_b, gap_vectors) -> dict[str, np.ndarray]:
    """The best-fit strain (3 x 3, E_ij = d(dl_i) / d(l_j)) of the grains' branch vectors from x0 to
    x1 ("total") and its exact split into PARTS, over the grain-to-grain contact records found at
    x0 (contact.model.ContactModel.grain_contacts): grains grain_a and grain_b of each record, and
    gap_vectors(field), p_A - p_B of each record at its material points for a field on the
    vertices. Raises ValueError where the records' branch vectors do not span 3-D."""
    a, b = np.asarray(grain_a), np.asarray(grain_b)
    t0, _, u0 = rigid_fits(reference, x0, vertex_ptr)
    t1, _, u1 = rigid_fits(reference, x1, vertex_ptr)
    l0, dl = t0[b] - t0[a], (t1[b] - t1[a]) - (t0[b] - t0[a])
    fit = l0.T @ l0
    if len(l0) < 3 or np.linalg.cond(fit) > 1e12:
        raise ValueError(f"branch_strain_split: {len(l0)} grain-to-grain contact records do not span 3-D")
    g0 = gap_vectors(x0)
    n = g0 / np.linalg.norm(g0, axis=1)[:, None]
    dg = gap_vectors(x1) - g0
    along = np.sum(dg * n, axis=1)[:, None] * n
    parts = {
        "deformation": gap_vectors(u1) - gap_vectors(u0),
        "contact_gap": -along,
        "tangential": -(dg - along),
    }
    parts["rotation"] = dl - sum(parts.values())
    inverse = np.linalg.inv(fit)
    out = {name: (part.T @ l0) @ inverse for name, part in parts.items()}
    out["total"] = (dl.T @ l0) @ inverse
    return out
