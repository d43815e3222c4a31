"""Explicit central differences with lumped mass (docs/dynamics.md).

Velocity Verlet form, which is central differences for the positions and allows a step that
changes from one step to the next:

    v_half = v_n + dt/2 a_n,   x_{n+1} = x_n + dt v_half,
    a_{n+1} = m^-1 [f_g - f_int(x_{n+1}) - r_c(x_{n+1}, v_half)],   v_{n+1} = v_half + dt/2 a_{n+1}

m is the lumped (row-sum) mass; the velocity-dependent contact terms (damping, friction) see the
half-step velocity. The forces are the same kernels as the implicit integrator's, without tangents.
Under selective mass scaling the drift x + dt v_half carries each grain's rigid motion out exactly
and turns its deformation velocity with it, and the kicks leave that free rotation out
(VemBodies.drift and accelerations, docs/selective-mass-scaling.md).

Stable step, recomputed every step (the safety factor covers the nonlinearity):
    dt = safety * min(2/omega_grain, min over pairs (sqrt(1 + zeta_p^2) - zeta_p) 2/omega_p, approach limit)
- omega_grain: the largest eigenvalue of each grain's (K, m) pair at rest, once per run;
- omega_p^2 = k(g) sum_i w_i^2 / m_i for each active pair, its weights w on its nodes' lumped
  masses (a wall node has 1/m = 0), k(g) the current contact stiffness: the exact eigenvalue of
  the pair's spring; zeta_p the damping ratio its normal damping really has on those masses
  (contact.ccd.damped_contact_step: 2-4 for the default zeta = 0.5);
- approach: no step may close more than `approach_fraction` of a pair's gap, at its exact gap rate
  for pairs in the activation layer, at a bound on the speed for pairs not yet in it.
A step whose end state is not admissible (a vertex behind a wall, an inverted element, a non-finite
force) is redone with half the step, as in the implicit integrator.

Contact candidates are kept in a Verlet list: searched with a skin, searched again when the
vertices (or the mesh walls) have moved half the skin since.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..contact.ccd import (
    damped_contact_step,
    grain_speeds,
    max_displacement,
    max_pair_speed,
    pair_gaps,
    plane_closing_time,
    plane_distances,
    rigid_pair_inverse_masses,
)
from ..contact.model import PenetrationError
from ..model.bodies import InvertedElementError
from ..model.scene import Scene
from .defaults import default
from .state import RunStats, State, StepControl, StepInfo, StepRejected, TimeStepTooSmall


# Skin of the narrow phase's feature list (contact/feature_list.py), in activation gaps: on the
# main job's collapse 2 gaps rebuild 38 of 501 grain pairs' lists per step, and skins of 1 to 4
# gaps cost the same within the machine's noise (docs/contact.md)
FEATURE_SKIN_GAPS = 2.0


@dataclass
class ExplicitParameters:
    safety: float = default("safety")  # share of the critical step taken
    approach_fraction: float = 0.25  # share of a gap a step may close, for pairs in the activation layer
    # share of the layer a pair outside it may enter in one step (not `[solver] entry_fraction`, the
    # implicit impact control's)
    layer_entry: float = 0.5
    skin_gaps: float = 2.0  # Verlet skin, in activation gaps
    mass_damping: float = default("mass_damping")  # alpha (1/s): Rayleigh mass-proportional damping force alpha m v


class ExplicitIntegrator:
    """State that persists between steps of one run: critical steps, inverse masses, Verlet list."""

    def __init__(self, scene: Scene, params: ExplicitParameters = ExplicitParameters()):
        self.scene = scene
        self.params = params
        bodies = scene.bodies
        # with selective mass scaling lambda the grains' own step is sqrt(1 + lambda) longer, and
        # a contact meets their scaled deformation inertia too (bodies.node_inverse_masses)
        self.grain_dt = float(bodies.critical_steps().min())
        self.scaling = getattr(bodies, "deformation_scaling", 0.0)
        self._lumped = bodies.lumped[:, None]  # gravity on the lumped masses: free fall is exact
        n_wall_nodes = len(scene.contact.wall_nodes(0.0))
        self.inv_mass_all = np.concatenate([1.0 / bodies.lumped, np.zeros(n_wall_nodes)])  # walls: rigid
        self.skin = params.skin_gaps * scene.contact.law.activation_gap
        nodes = bodies.node_inverse_masses() if self.scaling else 1.0 / bodies.lumped
        self.entry_inverse_mass = 2.0 * float(np.max(nodes))
        self._candidates = None
        # steps move grains a fraction of gbar: the narrow phase's feature pairs change little
        scene.contact.keep_feature_list(FEATURE_SKIN_GAPS * scene.contact.law.activation_gap)

    @property
    def f_grav(self) -> np.ndarray:
        # read at every step: a scenario may turn gravity between steps (the tilting box)
        return self._lumped * self.scene.gravity[None, :]

    # ---------------------------------------------------------------- Verlet list of candidates
    def _wall_offsets(self, t):
        return np.array([m.motion.displacement(t) for m in self.scene.contact.meshes]).reshape(-1, 3)

    def reset_search(self):
        self._candidates = None

    def candidates(self, x, t):
        c = self._candidates
        if c is not None:
            moved = max_displacement(x, c["x"])
            if self.scene.contact.meshes:
                moved += max_displacement(self._wall_offsets(t), c["walls"])
            if moved <= 0.5 * self.skin:
                return c["pairs"]
        pairs = self.scene.contact.search(x, t, margin=self.skin)
        self._candidates = {
            "x": x.copy(),
            "walls": self._wall_offsets(t),
            "pairs": pairs,
        }
        return pairs

    # ---------------------------------------------------------------- forces and the step
    def forces(self, x, v, t, history):
        """(acceleration, strain energy, contact result) at x with velocity v."""
        scene = self.scene
        el = scene.bodies.evaluate(x)
        cr = scene.contact.evaluate(x, t, self.candidates(x, t), history, v=v)
        acc = scene.bodies.accelerations(self.f_grav - el.force - cr.force, x, v) - self.params.mass_damping * v
        if not np.all(np.isfinite(acc)):
            raise StepRejected("non-finite force")
        return acc, el.total_energy, cr

    def stable_step(self, state: State, ints, floats) -> float:
        dt = self.grain_dt
        if len(ints):
            contact = self.scene.contact
            rigid = self._rigid_pair_inverse(state, ints, floats) if self.scaling else None
            dt = min(dt, damped_contact_step(self.inv_mass_all, ints, floats, contact.law_params,
                                             contact.masses_of_pairs(ints), contact.friction.damping_ratio,
                                             rigid, self.scaling))  # fmt: skip
        dt *= self.params.safety
        return min(dt, self.approach_limit(state, ints, floats))

    def _rigid_pair_inverse(self, state: State, ints, floats) -> np.ndarray:
        """Every pair's inverse mass along its normal as rigid grains of the lumped masses, in
        their current placement: what the scaled deformation modes leave a contact as lambda
        grows. The bound 1/M + rho^2 / I_min in its place kept the steps of a 40-grain triaxial
        at 2.3 times the rigid grains'."""
        mass, centre, axes, moments = self.scene.bodies.rigid_frames(state.x)
        x_all = self.scene.contact.all_positions(state.x, state.t)
        return rigid_pair_inverse_masses(x_all, ints, floats, centre, axes, mass, moments)

    def approach_limit(self, state: State, ints, floats) -> float:
        """Longest step in which no pair closes more than `approach_fraction` f of its gap:
        - pairs in the activation layer (ints, floats at state.x): dt <= f g / (-dg/dt), with the
          exact gap rate of their contact points (the change of rate within a step, a dt^2 / 2,
          is four orders below the gap at the steps taken);
        - everything farther than gbar may enter the layer by at most e gbar (`layer_entry`,
          0.5: still above the switch to the barrier at 0.3 gbar): dt <= e gbar / s over the
          Verlet-list pairs (pairs outside the list cannot meet before it is refreshed) and
          (max(d - gbar, 0) + e gbar) / s over the planes, s a bound on the approach speed: the
          relative centre speed plus r, each side's largest vertex speed about its centre.
        The bound on s is loose for spinning grains: used for pairs already in the layer (as
        before), it allowed 1.1e-6 s where the exact rates allow 4.8e-6 s (settling 515-grain pack).
        The entry is also kept stable: a pair that enters by p meets the stiffness k(p) within the
        step, which must then be below the pair's critical step (`entry_depth`); with a law far
        stiffer than the weight's a step of e gbar / s entered the layer at several times its
        critical step, and two cubes at 0.1 m/s each rebounded at 73 times that speed."""
        scene, f = self.scene, self.params.approach_fraction
        gbar = scene.contact.law.activation_gap
        G = scene.n_grains
        vptr = scene.bodies.vertex_ptr
        c, r = grain_speeds(state.v, scene.bodies.lumped, vptr)
        limit = np.inf
        if len(ints):
            rate = scene.contact.rates(state.x, state.v, state.t, ints, floats)
            closing = rate < 0
            if closing.any():
                limit = f * float(np.min(pair_gaps(floats)[closing] / -rate[closing]))
        pairs = self._candidates["pairs"] if self._candidates is not None else np.zeros((0, 2), np.int64)
        if len(pairs):
            speed = max_pair_speed(c, r, pairs, G, self._mesh_velocities(state.t))
            if speed > 0:  # all at least gbar apart: the fastest enters first
                limit = min(limit, self.entry_depth(speed) / speed)
        for plane in scene.contact.planes:
            if not plane.motion.active(state.t):
                continue
            n = plane.normal
            dist = plane_distances(state.x, vptr, plane.point_at(state.t), n)
            approach = -(c @ n) + plane.motion.velocity(state.t) @ n
            fastest = float(np.max(np.maximum(approach, 0.0) + r, initial=0.0))
            if fastest > 0:
                limit = min(limit, plane_closing_time(dist, approach, r, gbar, self.entry_depth(fastest) / gbar))
        return limit

    def entry_depth(self, speed: float) -> float:
        """How deep a pair closing at `speed` may enter the layer in one step: e gbar
        (`layer_entry`), and no deeper than the depth p at which the step p / speed is the
        critical step of the penalty's stiffness there, k(p) = n1 eps1 p^(n1 - 1), on the largest
        inverse mass a pair can have (`entry_inverse_mass`): safety 2 / sqrt(k(p) m^-1) = p / speed."""
        law = self.scene.contact.law
        n1, c = law.penalty_exponent, 2.0 * self.params.safety
        stable = (c * speed / np.sqrt(n1 * law.penalty * self.entry_inverse_mass)) ** (2.0 / (n1 + 1.0))
        return min(self.params.layer_entry * law.activation_gap, stable)

    def _mesh_velocities(self, t):
        return np.array([m.motion.velocity(t) for m in self.scene.contact.meshes]).reshape(-1, 3)

    def dissipative_residual(self, cr, v) -> np.ndarray:
        """r_d: the damping, friction and mass-damping part of the residual (minus their force),
        evaluated with the velocity the step used."""
        return cr.dissipative + self.params.mass_damping * self.scene.bodies.lumped[:, None] * v

    @staticmethod
    def step_dissipation(state: State, damping: np.ndarray, v_half: np.ndarray, v_moved: np.ndarray,
                         dt: float) -> float:  # fmt: skip
        """Energy the dissipative forces took over the step, as velocity Verlet applies them: each
        step's kinetic energy changes by dt/2 (F_n + F_n+1) . v_n+1/2 (+ a telescoping dt^2 term),
        so their work is dt/2 (r_d,n + r_d,n+1) . v_n+1/2; a trapezoid of the powers F_n . v_n-1/2
        and F_n+1 . v_n+1/2 mixes velocities and left the balance of a dropped grain 1-8 % off.
        The half-step velocity before the drift meets the first kick, the one after it (turned
        with the grains under selective mass scaling) the second."""
        before = state.bodies.get("dissipative")
        if before is None:
            before = damping
        return 0.5 * dt * float(np.sum(before * v_half) + np.sum(damping * v_moved))

    def step(self, state: State, dt: float) -> tuple[State, StepInfo]:
        v_half = state.v + 0.5 * dt * state.a
        x, v_moved = self.scene.bodies.drift(state.x, v_half, dt)
        t1 = state.t + dt
        try:
            acc, strain, cr = self.forces(x, v_moved, t1, state.history)
        except (InvertedElementError, PenetrationError) as exc:
            raise StepRejected(str(exc)) from None
        if len(cr.ints) and np.min(pair_gaps(cr.floats)) <= 0:
            raise StepRejected("a contact gap closed")
        v = v_moved + 0.5 * dt * acc
        damping = self.dissipative_residual(cr, v_moved)
        new = State(
            t1,
            x,
            v,
            acc,
            cr.trial_history,
            state.dissipated + self.step_dissipation(state, damping, v_half, v_moved, dt),
            float(np.sum(damping * v_moved)),
            {"dissipative": damping},
        )
        info = StepInfo(
            0,  # no Newton: summary.json's n_newton_iterations counts implicit steps' iterations only
            cr.n_contacts,
            cr.energy,
            strain,
            cr.wall_reactions,
            cr.ints,
            cr.floats,
            cr,
        )
        return new, info


def explicit_initial_state(scene: Scene, integrator: ExplicitIntegrator, x0=None, v0=None, t0: float = 0.0,
                           history=None) -> State:  # fmt: skip
    x = scene.bodies.reference.copy() if x0 is None else np.array(x0, float)
    v = np.zeros_like(x) if v0 is None else np.array(v0, float)
    acc, _, cr = integrator.forces(x, v, t0, history)
    return State(t0, x, v, acc, cr.trial_history, bodies={"dissipative": integrator.dissipative_residual(cr, v)})


def advance_explicit(integrator: ExplicitIntegrator, state: State, t_end: float, control: StepControl,
                     on_step=None, stats: RunStats | None = None) -> tuple[State, RunStats]:  # fmt: skip
    """Integrate from state.t to t_end with the stable step; control.dt_max caps it, control.dt_min
    stops the run, control.dt reports the last step taken."""
    stats = stats or RunStats()
    integrator.reset_search()  # a fresh search at every call: a resumed run repeats it exactly
    _, ints, floats = integrator.scene.contact.pairs(state.x, state.t, integrator.candidates(state.x, state.t))
    while state.t < t_end * (1 - 1e-12):
        h = min(integrator.stable_step(state, ints, floats), control.dt_max, t_end - state.t)
        while True:
            if h < control.dt_min and h < t_end - state.t:  # a short remainder up to t_end is fine
                raise TimeStepTooSmall(
                    f"time step {h:.3g} s fell below the minimum {control.dt_min:.3g} s at t = {state.t:.6g} s "
                    f"(last rejection: {stats.last_rejection or 'stable step limit'})"
                )
            try:
                new, info = integrator.step(state, h)
                break
            except StepRejected as exc:
                stats.reject(exc)
                h *= 0.5
        state = new
        ints, floats = info.ints, info.floats
        control.dt = h
        stats.accept(info)  # one iteration for an explicit step; the rigid implicit step's Newton counts
        if on_step is not None:
            on_step(state, info, h)
    return state, stats
