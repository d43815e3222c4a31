"""The linear-solver room (docs/linear-solvers.md): the grain-block GMRES and the direct solver against SciPy's
sparse LU and against each other, on random non-symmetric block systems and on real Newton systems
of grains in contact with friction; the rigid modes of the coarse space against the element tangent."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from vemdem.geometry import sand_grain
from vemdem.model.bodies import VemBodies
from vemdem.solver.linear import grain_block
from vemdem.solver.linear import (
    DirectSolver,
    GrainBlockSolver,
    LinearSolveDiverged,
    NewtonSystem,
    SingularSystemError,
    make_linear_solver,
    rigid_modes,
    solve,
)
from vemdem.solver.newmark import newton_blocks
from vemdem.vem.material import Material

from test_newton_system import touching_scene


def random_block_system(sizes=(24, 36, 30, 90, 12, 60), seed=0):
    """Dense non-symmetric blocks of mixed sizes (diagonally dominant) and a sparse coupling."""
    rng = np.random.default_rng(seed)
    dof_ptr = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    blocks = [rng.normal(size=(n, n)) + 3 * n * np.eye(n) for n in sizes]
    n = dof_ptr[-1]
    body = np.repeat(np.arange(len(sizes)), sizes)
    C = sp.random(n, n, density=0.01, random_state=seed, format="coo")
    keep = body[C.row] != body[C.col]
    C = sp.csr_matrix((C.data[keep], (C.row[keep], C.col[keep])), shape=(n, n))
    K = sp.block_diag(blocks, format="csr") + C
    return K.tocsr(), dof_ptr, rng.normal(size=n)


def real_system(shift=3.3e8):
    """A Newton matrix of three cubes in contact (friction, damping): non-symmetric. shift is the
    Newmark a1 = 1 / (beta dt^2): 3.3e8 for dt = 1e-4 s, 3.3e6 for 1e-3 s (beta 0.3025)."""
    scene = touching_scene()
    gbar = scene.contact.law.activation_gap
    x = scene.bodies.reference * np.array([1.0, 1.0, 1.0 - 0.1 * gbar / 3e-3])
    v = np.random.default_rng(1).normal(scale=1e-3, size=x.shape)
    cr = scene.contact.evaluate(x, 0.0, scene.contact.search(x, 0.0), v=v, a4=2e3, tangent=True)
    el = scene.bodies.evaluate(x, tangent=True, mass_shift=shift)
    blocks, coupling = newton_blocks(scene, el, cr)
    return NewtonSystem(blocks, scene.bodies.block_ptr, scene.bodies.dof_ptr, coupling, x)


def test_round_trip_and_product():
    K, dof_ptr, b = random_block_system()
    system = NewtonSystem.from_csr(K, dof_ptr)
    assert abs(system.to_csr() - K).max() == 0.0
    np.testing.assert_allclose(system.matvec(b), K @ b, rtol=1e-14, atol=1e-12 * abs(K).max())


@pytest.mark.parametrize("make", [DirectSolver, GrainBlockSolver])
def test_solvers_match_scipy_on_random_block_systems(make):
    K, dof_ptr, b = random_block_system()
    system = NewtonSystem.from_csr(K, dof_ptr)
    solver = make()
    solver.factor(system)
    x = solver.solve(b, 1e-12)
    reference = spla.spsolve(K.tocsc(), b)
    np.testing.assert_allclose(x, reference, rtol=1e-9, atol=1e-12 * np.abs(reference).max())


def test_real_newton_system_is_not_symmetric_and_both_solvers_agree():
    system = real_system()
    K = system.to_csr()
    assert abs(K - K.T).max() > 1e-12 * abs(K).max()  # friction: beyond round-off
    b = np.random.default_rng(2).normal(size=system.n)
    reference = spla.spsolve(K.tocsc(), b)
    for solver in (DirectSolver(), GrainBlockSolver(), make_linear_solver("auto")):
        solver.factor(system)
        x = solver.solve(b, 1e-10)
        assert np.linalg.norm(K @ x - b) <= 1e-9 * np.linalg.norm(b)
        np.testing.assert_allclose(x, reference, rtol=0, atol=1e-7 * np.abs(reference).max())


def test_the_rigid_mode_coarse_space_makes_the_iteration_count_small():
    """At the shift of a long step (dt = 1e-3 s) the grain blocks alone leave the grains' rigid
    motions to GMRES; the coarse space takes them (performance.md: 2 iterations; measured here:
    2 against 6 without it)."""
    system = real_system(shift=3.3e6)
    b = np.random.default_rng(3).normal(size=system.n)
    with_coarse, without = GrainBlockSolver(), GrainBlockSolver(coarse=False)
    for solver in (with_coarse, without):
        solver.factor(system)
        solver.solve(b, 1e-8)
    assert with_coarse.stats.last_iterations <= 3
    assert without.stats.last_iterations >= with_coarse.stats.last_iterations + 2


def test_non_symmetric_dense_solve_is_right():
    """The dense path once assumed symmetry (scipy's assume_a='sym' reads one triangle only)."""
    A = np.array([[4.0, 1.0, 0.0], [3.0, 5.0, 1.0], [0.0, -2.0, 6.0]])
    b = np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(A @ solve(A, b), b, rtol=1e-14)
    import scipy.linalg as la

    assert np.linalg.norm(A @ la.solve(A, b, assume_a="sym") - b) > 1e-3  # what the old call returned


@pytest.mark.parametrize("make", [DirectSolver, GrainBlockSolver])
def test_a_singular_system_names_the_cause(make):
    K, dof_ptr, b = random_block_system()
    K = K.tolil()
    K[40, :] = 0.0
    K[:, 40] = 0.0
    solver = make()
    with pytest.raises(SingularSystemError, match="singular tangent"):
        solver.factor(NewtonSystem.from_csr(K.tocsr(), dof_ptr))
        solver.solve(b)


def test_rigid_modes_are_the_null_space_of_a_free_grain():
    """K_int Z = 0 for the element tangent at rest: the six modes are exactly rigid motions."""
    grain = sand_grain(seed=2, size=1e-3, n_vertices=20)
    bodies = VemBodies([grain], Material(90e9, 0.16, 2200.0))
    K = bodies.tangent_matrix(bodies.evaluate(bodies.reference, tangent=True).blocks).toarray()
    Z = rigid_modes(bodies.reference, bodies.vertex_ptr)
    assert np.abs(K @ Z).max() <= 1e-9 * np.abs(K).max()
    assert np.linalg.matrix_rank(Z) == 6
    # and nothing else: one more displacement pattern has stiffness
    assert np.linalg.matrix_rank(np.hstack([Z, np.random.default_rng(0).normal(size=(len(Z), 1))])) == 7
    assert np.linalg.norm(K @ np.random.default_rng(0).normal(size=len(Z))) > 0


@pytest.mark.parametrize("dense_up_to", [10**6, 0])
def test_trajectories_agree_between_the_solvers(monkeypatch, dense_up_to):
    """Three cubes settling on each other in a box for 3 ms (friction, damping, a few hundred
    Newton solves): the grain-block and direct solvers give the same motion, with the coarse matrix
    factorised dense, or sparse with its LU kept across Newton matrices (inner GMRES)."""
    from vemdem.solver.newmark import NewmarkParameters, advance, initial_state
    from vemdem.solver.state import StepControl

    monkeypatch.setattr(grain_block, "DENSE_COARSE_BODIES", dense_up_to)
    scene = touching_scene()
    finals = []
    for name in ("direct", "grain-block"):
        params = NewmarkParameters(0.3025, 0.6, linear=make_linear_solver(name))
        state, stats = advance(scene, initial_state(scene), 3e-3, StepControl(dt=1e-5, dt_max=1e-4), params)
        finals.append((state.x, state.v, stats))
    (x1, v1, s1), (x2, v2, s2) = finals
    assert s1.accepted == s2.accepted and s2.krylov_iterations > 0 and s1.krylov_iterations == 0
    moved = np.abs(x1 - scene.bodies.reference).max()
    assert moved > 1e-7  # they did move
    assert np.abs(x1 - x2).max() <= 1e-6 * moved
    assert np.abs(v1 - v2).max() <= 1e-6 * np.abs(v1).max()
    block = params.linear.stats
    if dense_up_to == 0:  # kept LUs did work: fewer SuperLU factorisations than Newton matrices
        assert block.coarse_iterations > 0 and 0 < block.coarse_factorisations < block.factorisations


def test_a_step_keeps_no_coarse_lu_from_the_step_before(monkeypatch):
    """A kept coarse LU changes the coarse solves' rounding, so newmark_step drops it at each step
    (`forget`): a step is a function of its state and step alone, as a run resumed from a checkpoint
    inside a frame needs to continue to the same bits. The same step twice with one solver (the
    second after the first left its LU) and with a fresh solver: the same bits."""
    from vemdem.solver.newmark import NewmarkParameters, advance, initial_state, newmark_step
    from vemdem.solver.state import StepControl

    monkeypatch.setattr(grain_block, "DENSE_COARSE_BODIES", 0)
    scene = touching_scene()
    params = NewmarkParameters(0.3025, 0.6, linear=make_linear_solver("grain-block"))
    state, _ = advance(scene, initial_state(scene), 1e-3, StepControl(dt=1e-5, dt_max=1e-4), params)  # settling
    stats = params.linear.stats
    steps, lus = [], []
    for _ in range(2):
        lus.append(stats.coarse_factorisations)
        steps.append(newmark_step(scene, state, 1e-4, params)[0])
    assert stats.coarse_factorisations - lus[1] >= 1 and lus[1] - lus[0] >= 1  # each step its own first LU
    assert stats.coarse_iterations > 0  # and LUs kept inside the steps
    fresh = NewmarkParameters(0.3025, 0.6, linear=make_linear_solver("grain-block"))
    steps.append(newmark_step(scene, state, 1e-4, fresh)[0])
    for other in steps[1:]:
        np.testing.assert_array_equal(other.x, steps[0].x)
        np.testing.assert_array_equal(other.v, steps[0].v)


def _coarse_space(system):
    """The coarse space of `system` as the solver builds it: its products from the block LU's pass."""
    solver = GrainBlockSolver()
    solver.factor(system)
    return solver._coarse


def _coarse_correction(system, r):
    return _coarse_space(system).correction_and_product(r)[0]


def test_a_kept_coarse_lu_solves_the_next_coarse_matrix(monkeypatch):
    """The coarse LU of one Newton matrix, kept for the next (another step size, the contacts
    moved), preconditions GMRES on the new coarse matrix: the correction is the new matrix's own to
    the inner tolerance, and no second SuperLU factorisation is made."""
    monkeypatch.setattr(grain_block, "DENSE_COARSE_BODIES", 0)
    monkeypatch.setattr(grain_block, "KEPT_COARSE_RTOL", 1e-12)
    first, second = real_system(shift=3.3e6), real_system(shift=2.0e6)
    second.coupling = second.coupling * 1.2
    r = np.random.default_rng(6).normal(size=second.n)
    solver = GrainBlockSolver()
    solver.factor(first)
    solver.factor(second)
    assert solver._coarse.fresh is False
    kept, _ = solver._coarse.correction_and_product(r)
    own = _coarse_correction(second, r)
    assert np.abs(own - _coarse_correction(first, r)).max() > 1e-3 * np.abs(own).max()  # the matrices differ
    np.testing.assert_allclose(kept, own, rtol=0, atol=1e-9 * np.abs(own).max())
    assert solver.stats.coarse_factorisations == 1 and solver.stats.coarse_iterations > 0


def test_a_kept_coarse_lu_that_does_not_pay_is_replaced(monkeypatch):
    """A kept LU whose inner GMRES misses the tolerance within KEPT_COARSE_MAX iterations is
    replaced by the new matrix's own (the correction exact again), and a Newton matrix whose coarse
    solves needed more than KEPT_COARSE_BUDGET inner iterations hands no LU on; with
    `forget` between them every matrix is factorised."""
    monkeypatch.setattr(grain_block, "DENSE_COARSE_BODIES", 0)
    monkeypatch.setattr(grain_block, "KEPT_COARSE_MAX", 1)
    first, second = real_system(shift=3.3e6), real_system(shift=1e5)
    r = np.random.default_rng(7).normal(size=second.n)
    solver = GrainBlockSolver()
    solver.factor(first)
    solver.factor(second)
    y, _ = solver._coarse.correction_and_product(r)
    assert solver._coarse.fresh and solver.stats.coarse_factorisations == 2
    np.testing.assert_allclose(y, _coarse_correction(second, r), rtol=1e-12, atol=0)

    monkeypatch.setattr(grain_block, "KEPT_COARSE_MAX", 10)
    monkeypatch.setattr(grain_block, "KEPT_COARSE_BUDGET", 0)
    near = real_system(shift=2.0e6)
    solver = GrainBlockSolver()
    for system in (first, near, first):
        solver.factor(system)
        solver._coarse.correction_and_product(r)
    # the 2nd matrix used the 1st's LU and spent inner iterations: the 3rd factorises its own
    assert solver.stats.coarse_iterations > 0 and solver.stats.coarse_factorisations == 2 and solver._coarse.fresh

    solver = GrainBlockSolver()
    for system in (first, near, first):
        solver.forget()
        solver.factor(system)
    assert solver.stats.coarse_factorisations == 3


@pytest.mark.parametrize("dense_up_to", [10**6, 0])
def test_coarse_correction_is_the_galerkin_projection(monkeypatch, dense_up_to):
    """Z (Z^T K Z)^-1 Z^T r from the compiled 6 x 6 body blocks (dense LAPACK or sparse SuperLU
    path) against the same product formed with dense matrices."""
    from vemdem.solver.linear import grain_block

    monkeypatch.setattr(grain_block, "DENSE_COARSE_BODIES", dense_up_to)
    system = real_system(shift=3.3e6)
    Z = rigid_modes(system.positions, system.dof_ptr // 3)
    G = system.n_bodies
    body = np.repeat(np.arange(G), np.diff(system.dof_ptr))
    Zfull = np.zeros((system.n, 6 * G))
    for a in range(6):
        Zfull[np.arange(system.n), 6 * body + a] = Z[:, a]
    K = system.to_csr().toarray()
    r = np.random.default_rng(5).normal(size=system.n)
    reference = Zfull @ np.linalg.solve(Zfull.T @ K @ Zfull, Zfull.T @ r)
    coarse = _coarse_space(system)
    assert (coarse._dense is not None) == (dense_up_to > 0)
    # Z^T K Z cancels the stiffness of E = 90 GPa grains (rigid modes) down to the mass term, 1e-8 of
    # it: round-off of 1e-9 relative in any order of summation
    correction, _ = coarse.correction_and_product(r)
    np.testing.assert_allclose(correction, reference, rtol=1e-7, atol=1e-10 * np.abs(reference).max())


@pytest.mark.parametrize("coarse", [True, False])
def test_the_preconditioner_gives_its_product_with_the_matrix(coarse):
    """precondition(r) returns z = P^-1 r and K z formed without a product over the blocks (r + C B^-1 s,
    docs/linear-solvers.md): against K z from the assembled matrix, and z against the two-level
    formula written with dense matrices. A well-conditioned system, so that the coupling's part of
    K z stands far above round-off (on E = 90 GPa tangents it drowns in the products' rounding)."""
    K, dof_ptr, r = random_block_system()
    positions = np.random.default_rng(3).normal(size=(dof_ptr[-1] // 3, 3))
    system = NewtonSystem.from_csr(K, dof_ptr, positions)
    solver = GrainBlockSolver(coarse=coarse)
    solver.factor(system)
    K = K.toarray()
    z, w = solver.precondition(r)
    B = np.zeros_like(K)
    for a, b in zip(dof_ptr[:-1], dof_ptr[1:]):
        B[a:b, a:b] = K[a:b, a:b]
    y = np.zeros(len(r))
    if coarse:
        Z = rigid_modes(positions, dof_ptr // 3)
        body = np.repeat(np.arange(len(dof_ptr) - 1), np.diff(dof_ptr))
        Zfull = np.zeros((len(r), 6 * (len(dof_ptr) - 1)))
        for a in range(6):
            Zfull[np.arange(len(r)), 6 * body + a] = Z[:, a]
        y = Zfull @ np.linalg.solve(Zfull.T @ K @ Zfull, Zfull.T @ r)
    expected = y + np.linalg.solve(B, r - K @ y)
    np.testing.assert_allclose(z, expected, rtol=1e-10, atol=1e-12 * np.abs(expected).max())
    np.testing.assert_allclose(w, K @ z, rtol=0, atol=1e-12 * np.abs(r).max())
    assert np.abs(w - r).max() > 1e-3 * np.abs(r).max()  # the coupling's part is there, not only r


def test_coarse_block_pattern_is_that_of_the_coupling():
    """_coupling_pattern (one pass with a marker) against np.unique of every entry's body-pair key."""
    from vemdem.solver.linear.grain_block import _coupling_pattern

    K, dof_ptr, _ = random_block_system(sizes=(24, 36, 30, 90, 12, 60, 18, 45), seed=5)
    C = sp.csr_matrix(K - sp.block_diag([K[a:b, a:b] for a, b in zip(dof_ptr[:-1], dof_ptr[1:])]))
    C.eliminate_zeros()
    G = len(dof_ptr) - 1
    dof_body = np.repeat(np.arange(G, dtype=np.int64), np.diff(dof_ptr))
    keys, diagonal, slot = _coupling_pattern(C.indptr, C.indices, dof_ptr, dof_body)
    rows = np.repeat(np.arange(C.shape[0]), np.diff(C.indptr))
    entry_keys = dof_body[rows] * G + dof_body[C.indices]
    expected, inverse = np.unique(np.concatenate([np.arange(G) * (G + 1), entry_keys]), return_inverse=True)
    assert len(entry_keys) > 3 * G  # coupled: more than the diagonal
    np.testing.assert_array_equal(keys, expected)
    np.testing.assert_array_equal(diagonal, inverse[:G])
    np.testing.assert_array_equal(slot, inverse[G:])


@pytest.mark.parametrize("failure", ["gmres", "coarse"])
def test_auto_hands_a_failed_system_to_the_direct_solver(monkeypatch, failure):
    """Under a lid at the real density the grain-block path failed on some Newton systems (GMRES
    at its iteration cap; a coarse matrix too ill-conditioned to factor) that a direct solve takes:
    auto answers with the direct solution and counts the hand-over."""
    import vemdem.solver.linear as linear
    from vemdem.solver.linear import grain_block

    monkeypatch.setattr(linear, "DENSE_LIMIT", 0)  # the grain-block path even for three cubes
    system = real_system()
    K = system.to_csr()
    b = np.random.default_rng(4).normal(size=system.n)
    solver = make_linear_solver("auto")
    if failure == "gmres":
        solver.block.max_iterations = 1
    else:
        def ill_conditioned(*args):
            raise SingularSystemError("singular tangent (coarse space: singular matrix)")

        monkeypatch.setattr(grain_block, "_CoarseSpace", ill_conditioned)
    solver.factor(system)
    x = solver.solve(b, 1e-10)
    assert solver.stats.fallbacks == 1
    np.testing.assert_allclose(x, spla.spsolve(K.tocsc(), b), rtol=0, atol=1e-9 * np.abs(x).max())


def test_auto_hands_over_a_system_whose_coarse_matrix_fails_inside_the_solve(monkeypatch):
    """With a kept coarse LU the new coarse matrix is factorised only when the inner GMRES misses
    (inside the solve); a singular one there is handed to the direct solver like one found at set-up."""
    import vemdem.solver.linear as linear

    monkeypatch.setattr(linear, "DENSE_LIMIT", 0)
    monkeypatch.setattr(grain_block, "DENSE_COARSE_BODIES", 0)
    monkeypatch.setattr(grain_block, "KEPT_COARSE_MAX", 1)
    first, second = real_system(shift=3.3e6), real_system(shift=1e5)
    solver = make_linear_solver("auto")
    solver.factor(first)
    calls = []

    def singular(A):
        calls.append(A)
        raise RuntimeError("Factor is exactly singular")

    monkeypatch.setattr(grain_block, "superlu", singular)
    solver.factor(second)  # the first matrix's LU kept: no factorisation yet
    b = np.random.default_rng(8).normal(size=second.n)
    x = solver.solve(b, 1e-10)
    assert len(calls) == 1 and solver.stats.fallbacks == 1
    # a1 = 1e5 leaves the grains' stiffness 1e9 times their mass term: two direct solves agree to 1e-7
    np.testing.assert_allclose(x, spla.spsolve(second.to_csr().tocsc(), b), rtol=0, atol=1e-6 * np.abs(x).max())


def test_auto_holds_the_direct_solver_after_a_hand_over_and_tries_grain_block_again(monkeypatch):
    """A failed grain-block solve costs GMRES its whole budget; the systems after it are alike (a
    jammed pack stays jammed), so auto sends the next HOLD systems straight to the direct solver,
    doubles the hold while the grain-block path keeps failing, and resets it once it succeeds.
    Every answer is the direct solution."""
    import vemdem.solver.linear as linear

    monkeypatch.setattr(linear, "DENSE_LIMIT", 0)
    system = real_system()
    K = system.to_csr()
    b = np.random.default_rng(7).normal(size=system.n)
    exact = spla.spsolve(K.tocsc(), b)
    solver = make_linear_solver("auto")
    solver.block.max_iterations = 1  # GMRES fails on every system

    def run(n):
        for _ in range(n):
            solver.factor(system)
            x = solver.solve(b, 1e-10)
            np.testing.assert_allclose(x, exact, rtol=0, atol=1e-9 * np.abs(exact).max())

    run(1)
    assert (solver.stats.fallbacks, solver.stats.held) == (1, 0)
    run(solver.HOLD)  # held: no grain-block attempt
    assert (solver.stats.fallbacks, solver.stats.held) == (1, solver.HOLD)
    run(1)  # tried again, fails again: the hold doubles
    assert (solver.stats.fallbacks, solver.stats.held) == (2, solver.HOLD)
    run(2 * solver.HOLD)
    assert (solver.stats.fallbacks, solver.stats.held) == (2, 3 * solver.HOLD)
    solver.block.max_iterations = 200  # the pack unjams: grain-block succeeds and the hold resets
    run(1)
    assert solver._current is solver.block and solver.stats.fallbacks == 2
    solver.block.max_iterations = 1
    run(1 + solver.HOLD + 1)
    assert (solver.stats.fallbacks, solver.stats.held) == (4, 4 * solver.HOLD)


def test_forcing_follows_eisenstat_walker():
    """The Krylov tolerance of each Newton iteration (newmark._forcing): Eisenstat and Walker's
    choice 2, 0.9 (|R_k| / |R_k-1|)^2, safeguarded by 0.9 eta_k-1^2 when that exceeds 0.1, and
    kept between krylov_rtol and krylov_forcing."""
    from vemdem.solver.newmark import NewmarkParameters, _forcing

    p = NewmarkParameters(krylov_rtol=1e-8, krylov_forcing=0.1)
    assert _forcing(p, 0.1, None, 1.0) == 0.1  # the first iteration: the loosest
    assert _forcing(p, 0.1, 1.0, 0.1) == pytest.approx(0.9 * 0.01)  # 0.9 eta^2 = 0.009 < 0.1: no safeguard
    assert _forcing(p, 0.1, 1.0, 1e-6) == 1e-8  # quadratic convergence: down to krylov_rtol
    assert _forcing(p, 0.1, 1.0, 0.9) == 0.1  # a slow iteration: capped
    loose = NewmarkParameters(krylov_rtol=1e-8, krylov_forcing=0.9)
    assert _forcing(loose, 0.5, 1.0, 1e-3) == pytest.approx(0.9 * 0.25)  # safeguard: 0.9 * 0.5^2 > 0.1
    assert _forcing(NewmarkParameters(krylov_rtol=1e-8, krylov_forcing=0.0), 0.1, 1.0, 0.5) == 1e-8  # off


def test_inexact_newton_keeps_the_trajectory_and_saves_krylov_iterations():
    """The three cubes of test_trajectories_agree_between_the_solvers with grain-block GMRES solved
    to 1e-8 at every Newton iteration and with the Eisenstat-Walker forcing term: the same motion
    (Newton's own tolerance, 1e-8 of the step's displacement, bounds what either leaves) in fewer
    Krylov iterations."""
    from vemdem.solver.newmark import NewmarkParameters, advance, initial_state
    from vemdem.solver.state import StepControl

    scene = touching_scene()
    finals = []
    for forcing in (0.0, 0.1):
        params = NewmarkParameters(0.3025, 0.6, linear=make_linear_solver("grain-block"), krylov_forcing=forcing)
        state, stats = advance(scene, initial_state(scene), 3e-3, StepControl(dt=1e-5, dt_max=1e-4), params)
        finals.append((state.x, state.v, stats))
    (x1, v1, s1), (x2, v2, s2) = finals
    moved = np.abs(x1 - scene.bodies.reference).max()
    assert moved > 1e-7
    assert np.abs(x1 - x2).max() <= 1e-6 * moved
    assert np.abs(v1 - v2).max() <= 1e-6 * np.abs(v1).max()
    assert s2.krylov_iterations < 0.9 * s1.krylov_iterations  # 118 against 151 here
    assert s2.newton_iterations <= 1.1 * s1.newton_iterations


def test_block_lu_solves_every_block_and_flags_the_singular_ones():
    """The batched LAPACK factorisation (of each block's transpose, stored by rows) against NumPy's
    solve block by block, on blocks that need row interchanges (zero diagonal entries); a block
    with two equal rows or a NaN is flagged, the others are not. The coarse products the same pass
    forms (B_g Z_g, Z_g^T B_g Z_g) against NumPy's."""
    rng = np.random.default_rng(3)
    sizes = np.array([3, 12, 30, 90, 57, 6])
    dof_ptr = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    block_ptr = np.concatenate([[0], np.cumsum(sizes**2)]).astype(np.int64)
    mats = []
    for n in sizes:
        A = rng.normal(size=(n, n))
        A[np.arange(n), np.arange(n)] = 0.0  # every pivot must come from another row
        mats.append(A)
    blocks = np.concatenate([A.ravel() for A in mats])
    lu, piv, bad = np.empty_like(blocks), np.empty(dof_ptr[-1], np.int32), np.zeros(len(sizes), np.int64)
    z = grain_block.rigid_modes(rng.normal(size=(dof_ptr[-1] // 3, 3)), dof_ptr // 3)
    local, bz = np.empty((len(sizes), 6, 6)), np.empty((dof_ptr[-1], 6))
    every = np.zeros(len(sizes), np.bool_)
    grain_block._lu_blocks(blocks, block_ptr, dof_ptr, lu, piv, bad, z, local, bz, every)
    assert not bad.any()
    for g, A in enumerate(mats):  # the coarse products formed on the way: B_g Z_g and Z_g^T B_g Z_g
        part = slice(dof_ptr[g], dof_ptr[g + 1])
        np.testing.assert_allclose(bz[part], A @ z[part], rtol=1e-12, atol=1e-12 * np.abs(A).max())
        np.testing.assert_allclose(local[g], z[part].T @ A @ z[part], rtol=1e-12, atol=1e-11 * np.abs(A).max())
    r, out = rng.normal(size=dof_ptr[-1]), np.empty(dof_ptr[-1])
    grain_block._lu_solve_blocks(lu, piv, block_ptr, dof_ptr, r, out, every)
    for g, A in enumerate(mats):
        part = slice(dof_ptr[g], dof_ptr[g + 1])
        np.testing.assert_allclose(out[part], np.linalg.solve(A, r[part]), rtol=1e-8, atol=1e-10)
    # blocks marked to skip (the Woodbury path's) are neither solved nor factored
    skip = every.copy()
    skip[3] = True
    out[:] = np.nan
    grain_block._lu_solve_blocks(lu, piv, block_ptr, dof_ptr, r, out, skip)
    skipped = np.s_[dof_ptr[3] : dof_ptr[4]]
    assert np.isnan(out[skipped]).all() and not np.isnan(np.delete(out, skipped)).any()

    broken = blocks.copy()
    B = broken[block_ptr[2] : block_ptr[3]].reshape(30, 30)
    B[7] = B[11]
    broken[block_ptr[4] + 100] = np.nan
    bad[:] = 0
    none = np.empty((0, 6))
    grain_block._lu_blocks(broken, block_ptr, dof_ptr, lu, piv, bad, none, np.empty((0, 6, 6)), none, every)
    assert np.flatnonzero(bad).tolist() == [2, 4]
    bad[:] = 0
    skip[:] = False
    skip[2] = True
    grain_block._lu_blocks(broken, block_ptr, dof_ptr, lu, piv, bad, none, np.empty((0, 6, 6)), none, skip)
    assert np.flatnonzero(bad).tolist() == [4]


def test_gmres_ends_at_its_attainable_accuracy():
    """At long steps the block solves amplify round-off along the grains' rigid modes, and the true
    residual stops falling above what was asked (1e-9 here at a1 = 3.3e6, dt = 1e-3 s): the solve
    ends after the first restart that does not halve it instead of spending its whole budget."""
    system = real_system(shift=3.3e6)
    solver = GrainBlockSolver()
    solver.factor(system)
    b = np.random.default_rng(0).normal(size=system.n)
    x = solver.solve(b, 1e-15)
    relative = np.linalg.norm(b - system.matvec(x)) / np.linalg.norm(b)
    assert 1e-15 < relative <= grain_block.STALL_ACCEPT
    assert solver.stats.last_iterations < 10 and solver.stats.stalled == 1


def test_gmres_stalled_far_from_the_answer_fails_at_once():
    """Where the floor is above STALL_ACCEPT (a1 = 330, dt = 0.1 s: 7e-6) the solve fails after a few
    iterations (`auto` then hands the system to the direct solver without waiting for the budget)."""
    system = real_system(shift=330.0)
    solver = GrainBlockSolver()
    solver.factor(system)
    b = np.random.default_rng(0).normal(size=system.n)
    with pytest.raises(LinearSolveDiverged, match="stalled"):
        solver.solve(b, 1e-10)
    assert solver.stats.last_iterations < 20  # the budget is 200
