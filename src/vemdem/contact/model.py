"""The contact layer of a scene: grains, walls, search, forces, tangent and friction history.

Data flow per time step (docs/contact.md): `search` runs the broad phase once at the start
of a step; `evaluate` re-solves the LCPs of those candidates at every Newton iterate and returns
the contact potential, residual, tangent and the wall reactions; `commit` stores the friction
history of the converged state.

Walls are extra rigid nodes appended after the grains' vertices (x_all = [x; wall nodes]):
- a plane is one triangle (p, p + t1, p + t2) whose vertex-face LCP has no range limit, so the
  plane is infinite and its pairs share every kernel (forces, friction, tangent) with grains;
- a triangulated wall is an extra surface of the topology, searched against each grain's box.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import njit

from .broad import candidate_pairs, grain_boxes
from .defaults import FORCE_MULTIPLE
from .forces import (
    contact_points,
    csr_from_block_triplets,
    evaluate_contacts,
    force_on_side_a,
    gap_rates,
    local_tangent_matrix,
    pair_normals,
    pair_points,
    scatter_local_forces,
    scatter_pair_tangents,
)
from .friction import MU_D, MU_S, ZETA, FrictionLaw, dissipative_forces, dissipative_terms
from .feature_list import FeatureList
from .law import InterfaceLaw, normal_stiffness
from .narrow import VERTEX_FACE
from .pairs import FEATURE_A, FEATURE_B, FLOAT_COLS, GAP, GRAIN_A, GRAIN_B, INT_COLS, KIND, NODE0, find_contacts
from .topology import build_topology
from .walls import MeshWall, PlaneWall


class PenetrationError(FloatingPointError):
    """Two surfaces touch or a vertex is on the wrong side of a wall: the state is not admissible."""


# A gap at or below TOUCHING_GAP switch gaps is contact: the barrier's force there (F_ref 1e18 and
# more) is no longer a force, and the closest points' difference is round-off (the friction kernel
# divided by an exact 0 when a lid had closed on a vertex to 1e-18 m, in the 515-grain jam). Such a
# state is a penetration: the step is rejected and halved.
TOUCHING_GAP = 1e-9


@dataclass
class ContactHistory:
    """Friction state of the pairs active at the last converged step, sorted by key."""

    keys: np.ndarray
    c_prev: np.ndarray  # (m, 2)
    gt: np.ndarray  # (m, 3)
    stick: np.ndarray  # (m,) bool

    @classmethod
    def empty(cls):
        return cls(np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros((0, 3)), np.zeros(0, bool))

    def lookup(self, keys: np.ndarray):
        """(found, c_prev, gt, stick) for each key; new pairs start from zero with stick."""
        m = len(keys)
        if len(self.keys) == 0:
            return np.zeros(m, bool), np.zeros((m, 2)), np.zeros((m, 3)), np.ones(m, bool)
        idx = np.minimum(np.searchsorted(self.keys, keys), len(self.keys) - 1)
        found = self.keys[idx] == keys
        c_prev = np.where(found[:, None], self.c_prev[idx], 0.0)
        gt = np.where(found[:, None], self.gt[idx], 0.0)
        stick = np.where(found, self.stick[idx], True)
        return found, c_prev, gt, stick


def pair_keys(ints: np.ndarray) -> np.ndarray:
    """Identity of a pair across steps: its kind and the two features (not the contact point)."""
    return (ints[:, KIND] << 60) | (ints[:, FEATURE_A] << 30) | (ints[:, FEATURE_B] + (1 << 29))


@njit(cache=True)  # serial: a few flops per vertex, less than a parallel region's start-up on a busy machine
def _plane_records(x, n_vertices, node0, normals, body, face, vertex_grain, gbar, floor):
    """Vertex-face records of every vertex within gbar of a plane (planes in order, vertices in
    order within each). A plane's triangle starts at its point (x[node0]) and has orthogonal legs
    e1, e2 (_plane_frame), so the closest-point coordinates are plain projections, what
    vertex_face_lcp solves for a general triangle. Returns (ints, floats, wall, vertex): wall >= 0
    names the first plane with a vertex on its wrong side or within `floor` of it, and vertex the
    deepest one there."""
    P = len(node0)
    signed = np.empty((P, n_vertices))
    count = 0
    for w in range(P):
        p, nrm = x[node0[w]], normals[w]
        deepest, at = np.inf, -1
        for v in range(n_vertices):
            d = 0.0
            for a in range(3):
                d += (x[v, a] - p[a]) * nrm[a]
            signed[w, v] = d
            if d < deepest:
                deepest, at = d, v
            if d <= gbar:
                count += 1
        if deepest <= floor:
            return np.empty((0, INT_COLS), np.int64), np.empty((0, FLOAT_COLS)), w, at
    ints = np.full((count, INT_COLS), -1, np.int64)
    floats = np.empty((count, FLOAT_COLS))
    k = 0
    for w in range(P):
        n0 = node0[w]
        e1, e2 = x[n0 + 1] - x[n0], x[n0 + 2] - x[n0]
        e11 = e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]
        e22 = e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2]
        for v in range(n_vertices):
            # the counting pass's own test, `not <=` rather than `>`: a NaN distance fails both, so the
            # two passes agree and nothing is written past the `count` rows (heap corruption, seen)
            if not signed[w, v] <= gbar:
                continue
            ints[k, KIND] = VERTEX_FACE
            ints[k, GRAIN_A] = vertex_grain[v]
            ints[k, GRAIN_B] = body[w]
            ints[k, FEATURE_A] = v
            ints[k, FEATURE_B] = face[w]
            ints[k, NODE0] = v
            for j in range(3):
                ints[k, NODE0 + 1 + j] = n0 + j
            r0, r1, r2 = x[v, 0] - x[n0, 0], x[v, 1] - x[n0, 1], x[v, 2] - x[n0, 2]
            floats[k, 0] = (r0 * e1[0] + r1 * e1[1] + r2 * e1[2]) / e11
            floats[k, 1] = (r0 * e2[0] + r1 * e2[1] + r2 * e2[2]) / e22
            floats[k, 2] = signed[w, v]
            k += 1
    return ints, floats, -1, -1


@dataclass(frozen=True)
class ContactRecords:
    """The records of a ContactResult as plain arrays, one row per record (analysis.microstructure
    takes these: it may not import contact/). Bodies: grains 0..n_grains-1, then the walls (mesh
    walls, then planes, as in ContactModel.wall_names); a mesh wall may be either side."""

    a: np.ndarray  # (m,) side A's body
    b: np.ndarray  # (m,) side B's body
    kind: np.ndarray  # (m,) 0..3, contact.narrow.PAIR_NAMES: vertex-face, edge-edge, vertex-edge, vertex-vertex
    point: np.ndarray  # (m, 3) the contact point: midway between the two closest points
    normal: np.ndarray  # (m, 3) unit normal from B to A (forces.pair_normals)
    force: np.ndarray  # (m, 3) force on A from B (normal + damping + friction; B gets minus it)


@dataclass
class ContactResult:
    energy: float
    force: np.ndarray  # (N, 3) dPhi/dx on grain vertices (+ dissipative terms): minus the contact force
    pair_tangent: np.ndarray | None  # (m, 18, 18) d(force)/dx of each pair at its nodes (normal + dissipative)
    ints: np.ndarray
    floats: np.ndarray
    wall_reactions: np.ndarray  # (n_walls, 3) force of the grains on each wall
    trial_history: ContactHistory
    dissipation_power: float  # -F . v of damping and friction at this state (>= 0)
    local_forces: tuple  # (m, 6, 3) arrays of dPhi/dx at each pair's nodes: normal, then damping + friction
    dissipative: np.ndarray | None = None  # (N, 3) the damping and friction part of `force` (explicit energy books)

    @property
    def pair_force(self) -> np.ndarray:
        """(m, 3) physical force on side A of each pair (normal + damping + friction). Summed when
        asked (frames), not at every step: 0.3 ms of a 6 ms rigid step at 160 grains."""
        force = force_on_side_a(self.ints, self.local_forces[0])
        for local in self.local_forces[1:]:
            force = force + force_on_side_a(self.ints, local)
        return force

    @property
    def n_contacts(self) -> int:
        return len(self.ints)

    @property
    def tangent(self) -> sp.csr_matrix | None:
        """The contact tangent on the grains' vertex dofs (3N square; wall nodes are prescribed)."""
        if self.pair_tangent is None:
            return None
        n = len(self.force)
        all_nodes = int(self.ints[:, NODE0:].max()) + 1 if len(self.ints) else n
        K = local_tangent_matrix(self.ints, self.pair_tangent, max(all_nodes, n))
        return K[: 3 * n, : 3 * n].tocsr()

    def points(self, x_all: np.ndarray) -> np.ndarray:
        """(m, 3) contact point of every pair on its side B (frames show them)."""
        return contact_points(x_all, self.ints, self.floats) if len(self.ints) else np.zeros((0, 3))

    def records(self, x_all: np.ndarray) -> ContactRecords:
        """The records as plain arrays (ContactRecords); x_all: the positions with the walls' nodes
        (ContactModel.all_positions), as `points` takes them."""
        ints, floats = self.ints, self.floats
        if not len(ints):
            empty = np.zeros(0, np.int64)
            return ContactRecords(empty, empty, empty, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)))
        x_all = np.ascontiguousarray(x_all, dtype=float)
        sides = pair_points(x_all, ints, floats)
        return ContactRecords(ints[:, GRAIN_A].copy(), ints[:, GRAIN_B].copy(), ints[:, KIND].copy(),
                              0.5 * (sides[:, 0] + sides[:, 1]), pair_normals(x_all, ints, floats),
                              self.pair_force)  # fmt: skip

    def add_to_blocks(self, vertex_grain, vertex_ptr, block_ptr, blocks, touched=None) -> sp.csr_matrix:
        """Add the contact tangent's within-grain terms to the grains' dense blocks (in place) and
        return the grain-to-grain coupling as one CSR matrix: no sparse sum in Newton. touched
        (N,) bool, if given, is set where a vertex's own block received a term."""
        n = len(self.force)
        size = 36 * len(self.ints)  # node blocks: at most 6 x 6 per pair
        rows, cols, vals = np.empty(size, np.int64), np.empty(size, np.int64), np.empty((size, 3, 3))
        if touched is None:
            touched = np.zeros(n, np.bool_)
        if len(self.ints):
            m = scatter_pair_tangents(self.ints, self.pair_tangent, vertex_grain, vertex_ptr, block_ptr, n, blocks,
                                      rows, cols, vals, touched)  # fmt: skip
        else:
            m = 0
        indptr, indices, data = csr_from_block_triplets(rows[:m], cols[:m], vals[:m], n)
        return sp.csr_matrix((data, indices, indptr), shape=(3 * n, 3 * n))


class ContactModel:
    def __init__(self, reference: np.ndarray, faces_per_grain: list, vertex_ptr: np.ndarray, grain_mass: np.ndarray,
                 law: InterfaceLaw, friction: FrictionLaw = FrictionLaw(), planes=(), meshes=(),
                 scene_size: float | None = None):  # fmt: skip
        self.law = law
        self.law_params = law.packed()
        self.friction = friction
        self.friction_params = friction.packed()
        self.planes: list[PlaneWall] = list(planes)
        self.meshes: list[MeshWall] = list(meshes)
        # per wall body (meshes, then planes: their body indices after the grains)
        frictionless = np.array([w.frictionless for w in self.meshes + self.planes], bool)
        self._frictionless_body = frictionless if frictionless.any() else None
        self.n_grains = len(vertex_ptr) - 1
        self.n_vertices = int(vertex_ptr[-1])
        self.vertex_ptr = np.asarray(vertex_ptr, np.int64)
        self.grain_mass = np.asarray(grain_mass, float)
        size = scene_size or float(np.ptp(reference, axis=0).max())
        # plane triangles (p, p + s t1, p + s t2), t1, t2 an orthonormal basis of the plane
        self._plane_frames = [self._plane_frame(pl.normal, size) for pl in self.planes]
        self._plane_normals = np.array([pl.normal for pl in self.planes], float).reshape(-1, 3)
        self._wall_nodes_at = None  # (t, the wall nodes at t): wall_nodes' last answer
        self._wall_velocities_at = None  # the same for _wall_velocities
        mesh_vertices = [np.asarray(m.vertices, float) for m in self.meshes]
        surf_ptr = np.concatenate([self.vertex_ptr, self.n_vertices + np.cumsum([0] + [len(v) for v in mesh_vertices])[1:]])
        all_ref = np.vstack([reference] + mesh_vertices) if mesh_vertices else reference
        self.topology = build_topology(all_ref, list(faces_per_grain) + [np.asarray(m.faces) for m in self.meshes],
                                       surf_ptr)  # fmt: skip
        self.n_mesh_nodes = len(all_ref) - self.n_vertices
        self.plane_node0 = len(all_ref)  # plane nodes follow the mesh walls' nodes
        self.plane_face_base = len(self.topology.faces)
        self.feature_list: FeatureList | None = None  # keep_feature_list

    def keep_feature_list(self, skin: float) -> None:
        """Answer `pairs` from a Verlet list of feature pairs (contact/feature_list.py): the same
        records, found in a third of the time where grains move little between calls (the explicit
        integrators' steps: docs/contact.md)."""
        self.feature_list = FeatureList(skin)

    @staticmethod
    def _plane_frame(normal, size):
        t1 = np.cross(normal, [1.0, 0, 0] if abs(normal[0]) < 0.9 else [0, 1.0, 0])
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(normal, t1)
        return np.array([np.zeros(3), size * t1, size * t2])  # counter-clockwise seen from the normal side

    # ------------------------------------------------------------------ positions of wall nodes
    def wall_nodes(self, t: float) -> np.ndarray:
        """Positions of the walls' nodes at t (read-only; the walls' motions are prescribed, so the
        last time's positions are kept: a Newton iteration asks for them several times)."""
        key = (t, self._steerings())
        if self._wall_nodes_at is not None and self._wall_nodes_at[0] == key:
            return self._wall_nodes_at[1]
        nodes = [m.vertices_at(t) for m in self.meshes]
        nodes += [pl.point_at(t) + frame for pl, frame in zip(self.planes, self._plane_frames)]
        out = np.vstack(nodes) if nodes else np.zeros((0, 3))
        out.setflags(write=False)
        self._wall_nodes_at = (key, out)
        return out

    def _steerings(self) -> int:
        """How often the steered walls (contact.walls.ServoMotion) changed course: a wall's path at
        a time may change when it is steered, so the caches keyed on time carry this count too."""
        return sum(getattr(w.motion, "version", 0) for w in self.meshes + self.planes)

    def all_positions(self, x: np.ndarray, t: float) -> np.ndarray:
        return np.ascontiguousarray(np.vstack([x, self.wall_nodes(t)]))

    # ------------------------------------------------------------------ search (once per step)
    def search(self, x: np.ndarray, t: float, margin: float = 0.0) -> np.ndarray:
        """Candidate surface pairs: grain-grain from the grid, grain-mesh-wall by boxes. `margin`
        widens the search by the distance grains may travel before the next search (a skin)."""
        gbar = self.law.activation_gap + margin
        pairs = [candidate_pairs(x, self.vertex_ptr, gbar)]
        if self.meshes:
            x_all = self.all_positions(x, t)
            lo, hi = grain_boxes(x_all, self.topology.grain_vertex_ptr, 0.5 * gbar)
            G = self.n_grains
            for w, mesh in enumerate(self.meshes):
                if not mesh.motion.active(t):
                    continue
                k = G + w
                ok = np.all((hi[:G] >= lo[k]) & (hi[k] >= lo[:G]), axis=1)
                grains = np.flatnonzero(ok)
                pairs.append(np.column_stack([grains, np.full(len(grains), k)]))
        return np.vstack(pairs).astype(np.int64)

    # ------------------------------------------------------------------ pairs at a state
    def pairs(self, x: np.ndarray, t: float, candidates: np.ndarray, reach: float | None = None):
        """Eligible pairs within the activation gap (or within `reach`, to look ahead)."""
        x_all = self.all_positions(x, t)
        gbar = self.law.activation_gap if reach is None else reach
        if reach is None and self.feature_list is not None:
            ints, floats = self.feature_list.find(x_all, candidates, self.topology, gbar)
        else:
            ints, floats = find_contacts(x_all, candidates, self.topology, gbar)
        if len(floats) and floats[:, GAP].min() <= self.touching_gap:
            c = int(np.argmin(floats[:, GAP]))
            raise PenetrationError(f"grains {ints[c, GRAIN_A]} and {ints[c, GRAIN_B]} touch (gap {floats[c, GAP]:.3g} m, "
                                   f"within round-off of contact)")  # fmt: skip
        plane_ints, plane_floats = self._plane_pairs(x_all, t, gbar)
        return x_all, np.vstack([ints, plane_ints]), np.vstack([floats, plane_floats])

    @property
    def wall_names(self) -> list[str]:
        """The walls' names in the order of ContactResult.wall_reactions: mesh walls, then planes."""
        return [m.name for m in self.meshes] + [p.name for p in self.planes]

    def grain_contacts(self, x: np.ndarray, t: float):
        """(grain_a, grain_b, gap_vectors) of the grain-to-grain records at x (walls left out):
        gap_vectors(field) is p_A - p_B of every record at its material points, for positions or any
        other field (N, 3) on the grains' vertices (analysis.spring_back)."""
        _, ints, floats = self.pairs(x, t, self.search(x, t))
        mine = (ints[:, GRAIN_A] < self.n_grains) & (ints[:, GRAIN_B] < self.n_grains)
        ints, floats = np.ascontiguousarray(ints[mine]), np.ascontiguousarray(floats[mine])

        def gap_vectors(field: np.ndarray) -> np.ndarray:
            p = pair_points(np.ascontiguousarray(field, dtype=float), ints, floats)
            return p[:, 0] - p[:, 1]

        return ints[:, GRAIN_A].copy(), ints[:, GRAIN_B].copy(), gap_vectors

    @property
    def touching_gap(self) -> float:
        """Gaps at or below this are contact for every purpose (TOUCHING_GAP)."""
        return TOUCHING_GAP * self.law.switch_gap

    def approaching(self, x, v, t, reach: float):
        """(gap, gap rate, m_eq) of every pair closer than `reach` (the impact step limit)."""
        x_all, ints, floats = self.pairs(x, t, self.search(x, t, margin=reach - self.law.activation_gap), reach)
        v_all = np.vstack([v, self._wall_velocities(t)])
        return floats[:, GAP], gap_rates(x_all, v_all, ints, floats), self.masses_of_pairs(ints)

    def rates(self, x, v, t, ints, floats) -> np.ndarray:
        """d(gap)/dt of the pairs (ints, floats) found at x: the normal speed of their contact points."""
        v_all = np.vstack([v, self._wall_velocities(t)])
        return gap_rates(self.all_positions(x, t), v_all, ints, floats)

    def _plane_pairs(self, x_all, t, gbar):
        active = [w for w, plane in enumerate(self.planes) if plane.motion.active(t)]
        if not active:
            return np.zeros((0, INT_COLS), np.int64), np.zeros((0, FLOAT_COLS))
        w = np.asarray(active, np.int64)
        ints, floats, bad, v = _plane_records(x_all, self.n_vertices, self.plane_node0 + 3 * w, self._plane_normals[w],
                                              self.n_grains + len(self.meshes) + w, self.plane_face_base + w,
                                              self.topology.vertex_grain, gbar, self.touching_gap)  # fmt: skip
        if bad >= 0:
            grain = self.topology.vertex_grain[v]
            raise PenetrationError(f"vertex {v} (grain {grain}) is behind wall {self.planes[active[bad]].name!r} "
                                   f"(or within round-off of it)")  # fmt: skip
        return ints, floats

    # ------------------------------------------------------------------ forces
    def potential(self, x, t, candidates, frozen=None) -> float:
        """The contact potential sum Phi(d) alone (no friction, no tangent): a line-search merit."""
        x_all, ints, floats = _with_frozen(*self.pairs(x, t, candidates), frozen, self.law.activation_gap)
        return evaluate_contacts(x_all, ints, floats, self.law_params, len(x_all), False).total_energy

    def evaluate(self, x, t, candidates, history: ContactHistory | None = None, v=None, a4: float = 0.0,
                 tangent: bool = False, frozen: FrozenPairs | None = None,
                 slipping: np.ndarray | None = None, undamped: np.ndarray | None = None) -> ContactResult:  # fmt: skip
        """Contact energy, residual (dPhi/dx + dissipative terms), tangent and wall reactions.

        v: vertex velocities at this state and a4 = dv/dx (Newmark); None and 0 for statics.
        frozen: records kept whether or not the narrow phase finds them now (Newton's cycling pairs).
        slipping: sorted pair keys whose static friction broke in this step (Newton's stick-slip
        cycles, solver.newmark.NewmarkParameters.break_stick_cycles): judged as pairs that slipped
        at the last step, by mu_d.
        undamped: sorted pair keys without normal damping for the rest of this step (Newton's
        cycles on the damping's no-adhesion clamp, NewmarkParameters.hold_damping_cycles)."""
        x_all, ints, floats = _with_frozen(*self.pairs(x, t, candidates), frozen, self.law.activation_gap)
        n_all = len(x_all)
        conservative = evaluate_contacts(x_all, ints, floats, self.law_params, n_all, tangent)
        if np.isinf(conservative.total_energy):  # a kept (frozen) record closed to 0: not a gap the law can carry
            c = int(np.argmax(conservative.energy))
            raise PenetrationError(f"grains {ints[c, GRAIN_A]} and {ints[c, GRAIN_B]} touch (a kept pair's gap reached 0)")
        residual = conservative.force
        pair_tangent = conservative.local_tangent if tangent else None
        keys = pair_keys(ints)
        history = history or ContactHistory.empty()
        found, c_prev, gt_prev, stick_prev = history.lookup(keys)
        if slipping is not None and len(slipping):
            stick_prev &= ~np.isin(keys, slipping, assume_unique=True)
        stick_now, gt_now = stick_prev.copy(), np.zeros((len(ints), 3))
        power = 0.0
        dissipative = np.zeros((self.n_vertices, 3))
        local_forces = (conservative.local_force,)
        if self.friction.active and len(ints):
            v_all = np.zeros_like(x_all)
            if v is not None:
                v_all[: self.n_vertices] = v
                v_all[self.n_vertices :] = self._wall_velocities(t)
            local_force = np.zeros((len(ints), 6, 3))
            # the dissipative tangent is added into the conservative one in place (19 MB per array
            # at the 7,356 pairs of the 515-grain lid jam)
            local_tangent = pair_tangent if tangent else np.zeros((1, 18, 18))
            fr = self.pair_friction(ints)
            if undamped is not None and len(undamped):
                fr[np.isin(keys, undamped), ZETA] = 0.0
            _dissipative(self, x_all, v_all, a4, ints, c_prev, gt_prev, found, stick_prev, fr, tangent,
                         local_force, local_tangent, stick_now, gt_now)  # fmt: skip
            extra = np.zeros_like(x_all)
            scatter_local_forces(ints, local_force, extra)
            residual = residual + extra
            power = float(np.sum(extra * v_all))
            dissipative = extra[: self.n_vertices]
            local_forces = (conservative.local_force, local_force)
        reactions = self._wall_reactions(residual)
        N = self.n_vertices
        trial = ContactHistory(keys, floats[:, :2].copy(), gt_now, stick_now)
        order = np.argsort(keys, kind="stable")
        trial = ContactHistory(keys[order], trial.c_prev[order], trial.gt[order], trial.stick[order])
        return ContactResult(conservative.total_energy, residual[:N], pair_tangent, ints, floats, reactions, trial, power,
                             local_forces, dissipative)  # fmt: skip

    def max_wall_speed(self, t: float) -> float:
        return max((float(np.linalg.norm(w.motion.velocity(t))) for w in self.planes + self.meshes), default=0.0)

    def _wall_velocities(self, t):
        """Velocities of the walls' nodes at t (read-only, kept for the last t as wall_nodes)."""
        key = (t, self._steerings())
        if self._wall_velocities_at is not None and self._wall_velocities_at[0] == key:
            return self._wall_velocities_at[1]
        vel = [np.repeat(m.motion.velocity(t)[None, :], len(m.vertices), axis=0) for m in self.meshes]
        vel += [np.repeat(pl.motion.velocity(t)[None, :], 3, axis=0) for pl in self.planes]
        out = np.vstack(vel) if vel else np.zeros((0, 3))
        out.setflags(write=False)
        self._wall_velocities_at = (key, out)
        return out

    @property
    def walls_move(self) -> bool:
        """Whether any wall has a prescribed motion (a removal alone is not one)."""
        return any(w.motion.moves for w in self.meshes + self.planes)

    def reference_weight(self) -> float:
        """The grain weight the normal law was made for: its reference force (the force at the switch
        gap) over FORCE_MULTIPLE, the grain's own weight under the default weight law
        (contact/defaults.py), more where `reference_force` set the law for a lid's load."""
        return self.law.switch_force / FORCE_MULTIPLE

    def wall_stiffness(self, ints: np.ndarray, floats: np.ndarray) -> np.ndarray:
        """(n_walls,) the normal stiffness k(g) summed over each wall's records (in the order of
        wall_reactions): d(normal force)/d(wall travel) with the grains held, an upper bound of the
        sample's stiffness against that wall (a servo's gain: lab/servo.py)."""
        body = np.maximum(ints[:, GRAIN_A], ints[:, GRAIN_B])
        mine = body >= self.n_grains
        k = normal_stiffness(np.ascontiguousarray(floats[mine, GAP]), self.law_params)
        return np.bincount(body[mine] - self.n_grains, weights=k, minlength=len(self.meshes) + len(self.planes))

    def wall_work(self, t0: float, t1: float, reactions0: np.ndarray, reactions1: np.ndarray) -> float:
        """Work of the walls' prescribed motion on the grains from t0 to t1: minus the grains' force
        on each wall (the mean of its values at t0 and t1, the trapezoidal rule of a step) dotted
        with the wall's displacement. 0 where no wall moves (the reactions may then be None)."""
        if not self.walls_move:
            return 0.0
        walls = self.meshes + self.planes  # the order of ContactResult.wall_reactions
        shift = np.array([w.motion.displacement(t1) - w.motion.displacement(t0) for w in walls]).reshape(-1, 3)
        return -0.5 * float(np.sum((reactions0 + reactions1) * shift))

    def _wall_reactions(self, residual):
        """Force of the grains on each wall: minus the residual (dPhi/dx) summed over its nodes."""
        out = []
        start = self.n_vertices
        for m in self.meshes:
            out.append(residual[start : start + len(m.vertices)].sum(axis=0))
            start += len(m.vertices)
        for _ in self.planes:
            out.append(residual[start : start + 3].sum(axis=0))
            start += 3
        return -np.array(out).reshape(-1, 3)

    def pair_friction(self, ints) -> np.ndarray:
        """(m, 5) friction parameters of every pair (FrictionLaw.packed): the law's, with mu_s = mu_d = 0
        on the pairs of a frictionless wall."""
        fr = np.tile(self.friction_params, (len(ints), 1))
        if self._frictionless_body is not None and len(ints):
            G = self.n_grains
            slip = np.zeros(len(ints), bool)
            for side in (GRAIN_A, GRAIN_B):  # a mesh wall may be either side of a pair
                body = ints[:, side]
                wall = body >= G
                slip[wall] |= self._frictionless_body[body[wall] - G]
            fr[slip, MU_S] = fr[slip, MU_D] = 0.0
        return fr

    def masses_of_pairs(self, ints):
        """m_eq = m_A m_B / (m_A + m_B); a wall counts as infinitely heavy (m_eq = m_grain). A
        triangulated wall may be either side of a pair (its vertex on a grain's face: side A)."""
        G = self.n_grains
        gA, gB = ints[:, GRAIN_A], ints[:, GRAIN_B]
        mA = self.grain_mass[np.minimum(gA, G - 1)]
        mB = self.grain_mass[np.minimum(gB, G - 1)]
        return np.where(gA >= G, mB, np.where(gB >= G, mA, mA * mB / (mA + mB)))


@dataclass
class FrozenPairs:
    """Records (rows of ints and floats) kept in the eligible set while Newton iterates, whether or not
    the narrow phase finds them at the current iterate: a pair that leaves and rejoins the set every
    other iteration (its record ends where no other takes its force over) otherwise leaves Newton
    cycling between two residuals (solver.newmark.NewmarkParameters.freeze_cycles). A kept record's
    gap is measured at its closest-point coordinates of the iterate it was last found at, a smooth
    function of the node positions."""

    keys: np.ndarray  # sorted pair_keys
    ints: np.ndarray
    floats: np.ndarray


# Two records of the same two grains whose closest points lie within this share of gbar of each
# other on both sides describe one touching spot (gbar is the reach of the barrier): at a
# hand-over (a vertex-face pair that became the vertex-edge pair at the face's edge) or where the
# narrow phase finds an edge-edge pair at its edge's end beside the end vertex's own record.
# In the 515-grain lid jam such near twins lay 0.0004-0.11 gbar apart, the records whose force no
# other record carried 1.4-16 gbar (docs/dynamics.md).
TWIN_FRACTION = 0.5


def _with_frozen(x_all, ints, floats, frozen: FrozenPairs | None, gbar: float):
    """The narrow phase's records plus the frozen ones it did not find and that twin no found record
    (the same touching spot: its force is carried, adding it would count it twice), less the frozen
    ones it found that twin a record outside the frozen set: a twin that comes and goes (an
    edge-edge record at its edge's end beside the end vertex's vertex-face record) is held out for
    the rest of the step, so that the set Newton iterates on stays the same."""
    if frozen is None or not len(frozen.keys):
        return x_all, ints, floats
    found = np.isin(pair_keys(ints), frozen.keys)
    if found.any() and not found.all():
        held_out = np.zeros(len(ints), dtype=bool)
        held_out[found] = _twinned(x_all, ints[found], floats[found], ints[~found], floats[~found], TWIN_FRACTION * gbar)
        if held_out.any():
            ints, floats = ints[~held_out], floats[~held_out]
    missing = ~np.isin(frozen.keys, pair_keys(ints))
    if missing.any():
        missing[missing] = ~_twinned(x_all, frozen.ints[missing], frozen.floats[missing], ints, floats,
                                     TWIN_FRACTION * gbar)  # fmt: skip
    if not missing.any():
        return x_all, ints, floats
    return x_all, np.vstack([ints, frozen.ints[missing]]), np.vstack([floats, frozen.floats[missing]])


def _twinned(x_all, q_ints, q_floats, ints, floats, tol: float) -> np.ndarray:
    """For each query record, whether a record of (ints, floats) between the same two grains has
    the same two closest points (within tol, in either order of the sides)."""

    def grain_key(rows):
        lo, hi = np.minimum(rows[:, GRAIN_A], rows[:, GRAIN_B]), np.maximum(rows[:, GRAIN_A], rows[:, GRAIN_B])
        return (lo << 32) | hi

    q_key, key = grain_key(q_ints), grain_key(ints)
    near = np.flatnonzero(np.isin(key, q_key))
    if not len(near):
        return np.zeros(len(q_ints), dtype=bool)
    query = pair_points(x_all, q_ints, q_floats)[:, None]  # (query, 1, side, 3)
    found = pair_points(x_all, ints[near], floats[near])[None, :]  # (1, near, side, 3)
    direct = np.linalg.norm(found - query, axis=3).max(axis=2)
    swapped = np.linalg.norm(found[:, :, ::-1] - query, axis=3).max(axis=2)
    same_grains = key[near][None, :] == q_key[:, None]
    return ((np.minimum(direct, swapped) <= tol) & same_grains).any(axis=1)


def _dissipative(model, x_all, v_all, a4, ints, c_prev, gt_prev, found, stick_prev, fr, tangent,
                 local_force, local_tangent, stick_now, gt_now):  # fmt: skip
    common = (x_all, v_all, a4, ints, c_prev, gt_prev, found, stick_prev, model.law_params, fr,
              model.masses_of_pairs(ints), local_force)  # fmt: skip
    if tangent:
        dissipative_terms(*common, local_tangent, stick_now, gt_now)
    else:
        dissipative_forces(*common, stick_now, gt_now)
