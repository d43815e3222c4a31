"""The grain-block preconditioner's rotated-block Woodbury path (solver/linear/woodbury.py) against
dense linear algebra on real Newton matrices: its block solves' residuals, its coarse
products against the dense block's, its modal basis against its definition, and the GMRES solve
with it against the one with every block's LU."""

import numpy as np
import pytest

from vemdem.contact.defaults import default_contact_laws
from vemdem.contact.walls import box_walls
from vemdem.geometry import rotation_matrix, sand_grain
from vemdem.model.scene import Scene
from vemdem.solver.linear import GrainBlockSolver, rigid_modes
from vemdem.solver.linear.woodbury import WoodburyBlocks, modal_basis
from vemdem.solver.newmark import newton_system

from test_newton_system import MAT, touching_scene


def turned_system(shift, turn=0.3):
    """The three-cube stack of test_newton_system squeezed a little (strains below 1e-2), friction
    and damping active, turned as a whole by `turn` about the vertical axis: every grain's block is
    its reference block rotated, and contact terms touch some of its dofs."""
    scene = touching_scene()
    gbar = scene.contact.law.activation_gap
    x = scene.bodies.reference * np.array([1.0, 1.0, 1.0 - 0.1 * gbar / 3e-3])
    x = x @ rotation_matrix([0.0, 0.0, turn]).T
    v = np.random.default_rng(1).normal(scale=1e-3, size=x.shape)
    cr = scene.contact.evaluate(x, 0.0, scene.contact.search(x, 0.0), v=v, a4=2e3, tangent=True)
    el = scene.bodies.evaluate(x, tangent=True, mass_shift=shift, rotated_strain=1e-2)
    assert el.rotated.all()
    return newton_system(scene, el, cr, x, shift)


def mixed_system(shift):
    """Three sand grains of 12, 20 and 16 vertices stacked tip on tip half an activation gap apart on a
    floor (the modal basis batches grains by vertex count), friction and damping active, turned as one."""
    law, friction = default_contact_laws(1e-3, MAT.E, MAT.density, mu_s=0.6, mu_d=0.5)
    grains, top = [], np.array([0.0, 0.0, 0.5 * law.activation_gap])
    for k, n in enumerate((12, 20, 16)):
        g = sand_grain(seed=k, size=1e-3, n_vertices=n)
        low = g.vertices[np.argmin(g.vertices[:, 2])]
        g = g.translated(top - low)  # its lowest vertex right above the grain below's highest
        grains.append(g)
        top = g.vertices[np.argmax(g.vertices[:, 2])] + np.array([0.0, 0.0, 0.5 * law.activation_gap])
    scene = Scene.build(grains, MAT, law, friction, planes=box_walls(4e-3, 4e-3))
    x = scene.bodies.reference @ rotation_matrix([0.0, 0.0, 0.4]).T
    v = np.random.default_rng(4).normal(scale=1e-3, size=x.shape)
    cr = scene.contact.evaluate(x, 0.0, scene.contact.search(x, 0.0), v=v, a4=2e3, tangent=True)
    el = scene.bodies.evaluate(x, tangent=True, mass_shift=shift, rotated_strain=1e-2)
    assert el.rotated.all()
    return newton_system(scene, el, cr, x, shift)


def dense_block(s, g):
    n = s.dof_ptr[g + 1] - s.dof_ptr[g]
    return s.blocks[s.block_ptr[g] : s.block_ptr[g + 1]].reshape(n, n)


def test_modal_basis_diagonalises_the_reference_tangent_and_mass():
    s = turned_system(3.3e8)
    ref = s.reference
    basis = modal_basis(ref)
    for g in range(s.n_bodies):
        n, nv = s.dof_ptr[g + 1] - s.dof_ptr[g], (s.dof_ptr[g + 1] - s.dof_ptr[g]) // 3
        P = basis.phi[s.block_ptr[g] : s.block_ptr[g + 1]].reshape(n, n)
        K = ref.tangent[s.block_ptr[g] : s.block_ptr[g + 1]].reshape(n, n)
        M = np.kron(ref.mass[ref.mass_ptr[g] : ref.mass_ptr[g + 1]].reshape(nv, nv), np.eye(3))
        lam = basis.lam[s.dof_ptr[g] : s.dof_ptr[g + 1]]
        np.testing.assert_allclose(P.T @ M @ P, np.eye(n), atol=1e-10)
        np.testing.assert_allclose(P.T @ K @ P, np.diag(lam), atol=1e-9 * lam.max())
        # the reference's rigid modes are K's null space: what the coarse products rely on
        z = basis.z_ref[s.dof_ptr[g] : s.dof_ptr[g + 1]]
        assert np.abs(K @ z).max() <= 1e-10 * np.abs(K).max() * np.abs(z).max()
        np.testing.assert_allclose(basis.mz_ref[s.dof_ptr[g] : s.dof_ptr[g + 1]], M @ z, rtol=1e-13, atol=0)


@pytest.mark.parametrize("shift, make", [(3.3e8, turned_system), (3.3e6, turned_system), (3.3e8, mixed_system)])
def test_woodbury_block_solves_and_products_equal_the_dense_blocks(shift, make):
    s = make(shift)
    ref = s.reference
    wb = WoodburyBlocks(s, modal_basis(ref), max_dofs=99)
    assert wb.chosen.all() and (np.diff(wb.tptr) > 0).all()  # every grain, each with contact terms
    z = rigid_modes(s.positions, s.dof_ptr // 3)
    local, bz = np.empty((s.n_bodies, 6, 6)), np.empty_like(z)
    bad = np.zeros(s.n_bodies, np.int64)
    wb.factor(s, z, local, bz, bad)
    assert not bad.any()
    r = np.random.default_rng(2).normal(size=s.n)
    out = np.full(s.n, np.nan)
    wb.solve(s, r, out)
    for g in range(s.n_bodies):
        d = slice(s.dof_ptr[g], s.dof_ptr[g + 1])
        B = dense_block(s, g)
        # backward stable as the LU is (the blocks' condition numbers reach 1e8 at the small shift,
        # so forward errors of either solve do too): the residual is round-off of |B| |y|
        residual = np.abs(B @ out[d] - r[d]).max()
        assert residual <= 1e-14 * np.abs(B).max() * np.abs(out[d]).max()
        # the coarse rows: rigid modes of the rotated grain, and B Z without the dense block
        np.testing.assert_allclose(bz[d], B @ z[d], rtol=0, atol=1e-10 * np.abs(B).max() * np.abs(z[d]).max())
        np.testing.assert_allclose(local[g], z[d].T @ B @ z[d], rtol=0, atol=1e-10 * np.abs(B).max() * 30)


def test_gmres_with_the_woodbury_path_solves_the_newton_system_as_with_every_lu():
    s = turned_system(3.3e8)
    K = s.to_csr()
    b = np.random.default_rng(3).normal(size=s.n)
    solutions, iterations = [], []
    for max_dofs in (39, 0):
        solver = GrainBlockSolver(woodbury_max_dofs=max_dofs)
        solver.factor(s)
        assert (solver._woodbury is not None) == (max_dofs > 0)
        assert solver.stats.woodbury_blocks == (s.n_bodies if max_dofs > 0 else 0)
        x = solver.solve(b, rtol=1e-10)
        assert np.linalg.norm(K @ x - b) <= 1e-10 * np.linalg.norm(b)
        solutions.append(x)
        iterations.append(solver.stats.last_iterations)
    np.testing.assert_allclose(solutions[0], solutions[1], rtol=0, atol=1e-8 * np.abs(solutions[1]).max())
    assert iterations[0] <= iterations[1] + 1


def test_grains_touched_on_more_dofs_than_the_bound_keep_their_lu():
    s = turned_system(3.3e8)
    ref = s.reference
    basis = modal_basis(ref)
    k = np.add.reduceat(s.touched.astype(int), s.dof_ptr[:-1] // 3) * 3
    bound = int(np.median(k))
    wb = WoodburyBlocks(s, basis, max_dofs=bound)
    np.testing.assert_array_equal(wb.chosen, k <= bound)
    unrotated = s.rotated.copy()
    unrotated[0] = False
    s.rotated = unrotated
    assert not WoodburyBlocks(s, basis, max_dofs=99).chosen[0]
