#!/usr/bin/env python3
"""Independent finite-element reference for the soft-body solver (static hyperelasticity).

What: static solutions of two small problems -- a cantilever sagging under its own weight and
a block squeezed between frictionless plates -- computed with scikit-fem (a finite-element
library nobody in this project wrote) for the *same* material model our own solver uses: the
stable Neo-Hookean energy of Smith et al. 2018 in the form of Macklin & Mueller 2021 (see
softbody/src/methods/pbd/neohookean.rs, energy_density, and softbody/src/methods/reference.rs,
our XPBD accuracy reference). Our XPBD reference is compared with these numbers; this file
never reads anything from our solver.

    Psi(F) = mu/2 (I_C - 3) + lam'/2 (J - gamma)^2 - lam'/2 (1 - gamma)^2   [J / m^3 of rest volume]
    I_C = tr(F^T F),  J = det F,  lam' = lam + mu,  gamma = 1 + mu / lam',
    mu = E / (2 (1 + nu)),  lam = E nu / ((1 + nu)(1 - 2 nu)),  nu = 0.4 everywhere.

Linearised at rest this is plain linear elasticity with E and nu, which scikit-fem's own
`linear_elasticity` form also solves (the small-deflection cross-check).

How: total Lagrangian, Newton's method with an energy line search and adaptive load stepping
(the load -- gravity or the plate displacement -- is raised in increments; a step whose Newton
iteration fails is halved). First Piola stress P = mu F + lam' (J - gamma) cof F and its exact
tangent. scikit-fem supplies the meshes (MeshTet.init_tensor: each hexahedron split into six
tets), the Lagrange elements (ElementTetP1, ElementTetP2 = quadratic tets), their gradients
and quadrature, dof numbering and boundary dofs, the body-force load and the linear-elastic
stiffness. The Neo-Hookean force and tangent are contracted per quadrature point with numpy
(scikit-fem's generic form assembly is ~100x slower for a 30x30 vector-P2 tangent); that
kernel is checked on every run of --check against the same quantities assembled through
scikit-fem's BilinearForm/LinearForm (written independently with skfem.helpers), against
scikit-fem's linear_elasticity at rest, and against finite differences.

Run (through the wrapper, which makes the pinned virtualenv):

    scripts/fem-reference --all     every problem at every level; writes
                                    docs/results/methods/fem/{fem.csv,fem.md,answers.json}
    scripts/fem-reference --check   small levels only (seconds): compares with the committed
                                    scripts/fem/check.json (relative 1e-6) and the compression
                                    against its analytic answer; exit 1 on any mismatch
    scripts/fem-reference --bless   recomputes the --check values and rewrites check.json
    scripts/fem-reference --stability [--fine]
                                    stability of the compression's homogeneous solution: the
                                    smallest eigenvalue of the free-dof tangent stiffness at
                                    s = 0.05 ... 0.7 and the strain where it crosses zero, for
                                    P1 k = 1, 2, 4, 8 and P2 k = 1, 2, 4 (under a minute; --fine
                                    adds P2 k = 8, ~5 min, 1 GB); writes
                                    docs/results/methods/fem/{stability.csv,stability.txt}
                                    (RESULT reference.fem_stability lines); leaves the other
                                    outputs alone

Pinned versions (installed by scripts/fem-reference): scikit-fem==12.0.2, numpy==2.4.6,
scipy==1.17.1 (Python 3.11). Units: SI inside (m, Pa, N, kg); reported in mm and N.
"""

import argparse
import csv
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
import scipy
import scipy.sparse as sp
import scipy.sparse.linalg as sla
import skfem
from skfem import (Basis, BilinearForm, ElementTetP1, ElementTetP2, ElementVector,
                   LinearForm, MeshTet, asm)
from skfem.helpers import ddot, det, grad, inv, transpose
from skfem.models.elasticity import lame_parameters, linear_elasticity

ROOT = Path(__file__).resolve().parents[2]
OUT_DIR = ROOT / "docs" / "results" / "methods" / "fem"
CHECK_FILE = Path(__file__).resolve().parent / "check.json"
PINS = {"scikit-fem": "12.0.2", "numpy": "2.4.6", "scipy": "1.17.1"}

NU = 0.4            # Poisson's ratio, everywhere
RHO = 1000.0        # density, kg/m^3
GRAVITY = 9.81      # m/s^2, along -y
CHECK_RTOL = 1e-6   # --check: relative tolerance against check.json and the analytic answer

# Cantilever: box [0, 0.16] x [0, 0.04] x [0, 0.04] m, clamped at x = 0, own weight along -y.
BEAM = (0.16, 0.04, 0.04)
BEAM_MODULI = (("1e6", 1e6), ("1e5", 1e5))   # Young's modulus, Pa
# Compression: cube of side 0.04 m between frictionless plates, E = 2e5 Pa, engineering
# strains s (the top plate moves down by s * 0.04 m).
CUBE = 0.04
CUBE_E = 2e5
STRAINS = (0.1, 0.2, 0.4, 0.7)

# Levels: elements along y and z (4x that along x for the beam), and per side for the cube.
BEAM_LEVELS = (2, 4, 8)
CUBE_LEVELS = (1, 2, 4)
CONVERGED_PCT = 1.0  # P2 change between the two finest levels that counts as converged

# Newton: converged when the free-dof residual is below NEWTON_RTOL times the force scale
# (norm of the external load plus all internal nodal forces, reactions included).
NEWTON_RTOL = 1e-10
NEWTON_MAXIT = 25
GMRES_FORCING = 1e-5   # inexact Newton: relative residual accepted from a preconditioned GMRES


# --------------------------------------------------------------------------------------
# Material: stable Neo-Hookean (numpy, arrays of 3x3 matrices on the two leading axes)
# --------------------------------------------------------------------------------------

def snh_parameters(young_pa):
    """(mu, lam', gamma) of the stable Neo-Hookean model for Young's modulus `young_pa`, Pa."""
    lam, mu = lame_parameters(young_pa, NU)
    lam_p = lam + mu
    return mu, lam_p, 1.0 + mu / lam_p


def _cross(a, b):
    """Cross product of vectors on axis 0."""
    return np.stack([a[1] * b[2] - a[2] * b[1],
                     a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def cofactor(f):
    """cof F = dJ/dF = J F^-T: columns f1 x f2, f2 x f0, f0 x f1 (defined for any J)."""
    return np.stack([_cross(f[:, 1], f[:, 2]),
                     _cross(f[:, 2], f[:, 0]),
                     _cross(f[:, 0], f[:, 1])], axis=1)


# Levi-Civita symbol, for d(cof F)_iJ / dF_kL = eps_ikm eps_JLN F_mN.
EPS = np.zeros((3, 3, 3))
for _i, _j, _k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
    EPS[_i, _j, _k], EPS[_i, _k, _j] = 1.0, -1.0


def snh_energy(f, mu, lam_p, gamma):
    """Energy density Psi(F), J per m^3 of rest volume (zero at rest)."""
    ic = np.einsum("iJ...,iJ...->...", f, f)
    j = det(f)
    return 0.5 * mu * (ic - 3.0) + 0.5 * lam_p * ((j - gamma) ** 2 - (1.0 - gamma) ** 2)


def snh_stress(f, mu, lam_p, gamma):
    """First Piola stress P = dPsi/dF = mu F + lam' (J - gamma) cof F, Pa."""
    return mu * f + lam_p * (det(f) - gamma) * cofactor(f)


def snh_tangent(f, mu, lam_p, gamma):
    """A_iJkL = dP_iJ / dF_kL = mu d_ik d_JL + lam' cof_iJ cof_kL
    + lam' (J - gamma) eps_ikm eps_JLN F_mN, Pa (shape 3,3,3,3,...)."""
    cof = cofactor(f)
    a = lam_p * np.einsum("iJ...,kL...->iJkL...", cof, cof)
    a += lam_p * (det(f) - gamma) * np.einsum("ikm,JLN,mN...->iJkL...", EPS, EPS, f,
                                              optimize=True)
    for i in range(3):
        for jj in range(3):
            a[i, jj, i, jj] += mu
    return a


def uniaxial_analytic(young_pa, strain):
    """Homogeneous uniaxial compression of the stable Neo-Hookean material (the exact solution
    of the `compress` problem): axial stretch b = 1 - s, lateral stretch a with zero lateral
    stress. With F = diag(a, b, a): cof F = diag(ab, a^2, ab), J = a^2 b, and
        P_xx = mu a + lam' (J - gamma) a b = 0  =>  J = gamma - mu / (lam' b),  a^2 = J / b,
        P_yy = mu b + lam' (J - gamma) a^2 = mu (b - a^2 / b).
    Returns (force N, compression positive, = -P_yy * 0.04^2; bulge mm = (a - 1) * 0.04)."""
    mu, lam_p, gamma = snh_parameters(young_pa)
    b = 1.0 - strain
    a = math.sqrt((gamma - mu / (lam_p * b)) / b)
    # the closed form must zero the lateral stress of the generic stress function too
    p = snh_stress(np.diag([a, b, a])[:, :, None], mu, lam_p, gamma)[:, :, 0]
    assert abs(p[0, 0]) < 1e-9 * young_pa and abs(p[2, 2]) < 1e-9 * young_pa
    return -p[1, 1] * CUBE ** 2, (a - 1.0) * CUBE * 1e3


# --------------------------------------------------------------------------------------
# Discretisation: scikit-fem mesh, elements, quadrature; Neo-Hookean force and tangent
# --------------------------------------------------------------------------------------

class Discretisation:
    """A vector Lagrange space (P1 or P2 tets) on `mesh`, with what the Newton solver needs:
    internal nodal forces, elastic energy and tangent stiffness of the Neo-Hookean material,
    assembled from scikit-fem's basis-function gradients and quadrature."""

    def __init__(self, mesh, order):
        self.mesh = mesh
        self.order = order
        elem = ElementTetP1() if order == 1 else ElementTetP2()
        # default quadrature: degree 2 for P1 (F constant per tet), degree 4 (11 points) for P2
        self.vb = Basis(mesh, ElementVector(elem))
        sb = Basis(mesh, elem, quadrature=self.vb.quadrature)
        self.nloc = sb.Nbfun                               # scalar functions per tet
        # dN[a, J, e, q]: gradient of scalar basis function a (reference coordinates, 1/m)
        self.dn = np.array([sb.basis[a][0].grad for a in range(self.nloc)])
        self.dx = self.vb.dx                               # quadrature weight x volume, m^3
        # vector local dof 3a + i = component i of scalar function a (ElementVector order)
        self.edofs = self.vb.element_dofs                  # (3 nloc, n_elements)
        self.ndofs = int(self.vb.N)
        n = 3 * self.nloc
        self._rows = np.broadcast_to(self.edofs[:, None, :], (n, n, self.edofs.shape[1])).ravel()
        self._cols = np.broadcast_to(self.edofs[None, :, :], (n, n, self.edofs.shape[1])).ravel()

    def deformation_gradient(self, u):
        """F = I + Grad u at every quadrature point, shape (3, 3, n_elements, n_points)."""
        ue = u[self.edofs].reshape(self.nloc, 3, -1)
        f = np.einsum("aie,aJeq->iJeq", ue, self.dn)
        for i in range(3):
            f[i, i] += 1.0
        return f

    def min_volume_ratio(self, u):
        """Smallest det F over the quadrature points."""
        return float(det(self.deformation_gradient(u)).min())

    def forces(self, u, mat):
        """Internal nodal forces f_int = int P : Grad phi dV (N) and elastic energy (J)."""
        f = self.deformation_gradient(u)
        p = snh_stress(f, *mat)
        fe = np.einsum("iJeq,aJeq,eq->aie", p, self.dn, self.dx, optimize=True)
        fint = np.bincount(self.edofs.ravel(), fe.reshape(3 * self.nloc, -1).ravel(),
                           minlength=self.ndofs)
        energy = float(np.sum(snh_energy(f, *mat) * self.dx))
        return fint, energy

    def tangent(self, u, mat):
        """Tangent stiffness K = int Grad phi_a : A : Grad phi_b dV, N/m (sparse, CSR)."""
        a = snh_tangent(self.deformation_gradient(u), *mat)
        # ke[a, i, b, k, e] = sum_q dN_aJ A_iJkL dN_bL dx, in two contractions
        w = np.einsum("aJeq,iJkLeq,eq->aikLeq", self.dn, a, self.dx, optimize=True)
        ke = np.einsum("aikLeq,bLeq->aibke", w, self.dn, optimize=True)
        n = 3 * self.nloc
        k = sp.coo_matrix((ke.reshape(n, n, -1).ravel(), (self._rows, self._cols)),
                          shape=(self.ndofs, self.ndofs))
        return k.tocsr()

    def linear_stiffness(self, young_pa):
        """scikit-fem's own linear-elastic stiffness for (E, nu), N/m."""
        return asm(linear_elasticity(*lame_parameters(young_pa, NU)), self.vb)

    def gravity_load(self):
        """Nodal forces of the body force rho g along -y (dead load on the rest volume), N."""
        return asm(LinearForm(lambda v, w: -RHO * GRAVITY * v[1]), self.vb)

    def face_vertices(self, axis, coord):
        """Mesh vertices on the plane x_axis = coord (the (k+1)^2 grid of a box face)."""
        return np.nonzero(np.isclose(self.mesh.p[axis], coord, atol=1e-12))[0]

    def vertex_dofs(self, vertices, component):
        """Global dofs of displacement `component` at mesh `vertices`."""
        return self.vb.nodal_dofs[component, vertices]


def box(lx, ly, lz, nx, ny, nz):
    """Tet mesh of [0, lx] x [0, ly] x [0, lz] m, nx x ny x nz cubes of six tets each."""
    return MeshTet.init_tensor(np.linspace(0, lx, nx + 1), np.linspace(0, ly, ny + 1),
                               np.linspace(0, lz, nz + 1))


# --------------------------------------------------------------------------------------
# Linear and nonlinear solvers
# --------------------------------------------------------------------------------------

def factor(k):
    """Sparse LU of a symmetric matrix (minimum-degree ordering on A^T + A: ~2x faster and
    thinner than SuperLU's default for 3D elasticity)."""
    return sla.splu(k.tocsc(), permc_spec="MMD_AT_PLUS_A",
                    options=dict(SymmetricMode=True))


class TangentSolver:
    """Solves the Newton systems. Small systems: one LU per solve. Large ones (over
    `reuse_above` unknowns): up to 12 GMRES iterations preconditioned with the last LU,
    refactoring only when that is not enough (a new LU of a P2 k = 8 beam costs 10-20 s, a preconditioned
    iteration ~0.2 s). A GMRES answer is kept when its true residual is below GMRES_FORCING
    of the right-hand side (on these ill-conditioned P2 systems the true residual stalls well
    above the preconditioned one): an inexact Newton step, which still drives the nonlinear
    residual to NEWTON_RTOL, only perhaps one iteration later. Small systems: exact Newton."""

    def __init__(self, reuse_above=20000, lu=None):
        self.reuse_above = reuse_above
        self.lu = lu          # optional seed, e.g. the LU of the linear-elastic stiffness
        self.factorisations = 0

    def solve(self, k, r):
        if self.lu is not None and k.shape[0] > self.reuse_above:
            prec = sla.LinearOperator(k.shape, self.lu.solve)
            x, _ = sla.gmres(k, r, M=prec, rtol=1e-9, atol=0.0, restart=12, maxiter=1)
            if np.linalg.norm(k @ x - r) <= GMRES_FORCING * np.linalg.norm(r):
                return x
        self.lu = factor(k)
        self.factorisations += 1
        return self.lu.solve(r)


class NotConverged(RuntimeError):
    pass


def newton(disc, mat, u, free, fext, solver, log):
    """Newton's method from `u` (prescribed dofs already set) for f_int(u) = fext on the free
    dofs, with a backtracking line search on the potential energy. Returns (u, iterations).
    Raises NotConverged on divergence, inversion (det F <= 0) or too many iterations."""
    if disc.min_volume_ratio(u) <= 0.0:
        raise NotConverged("inverted predictor")
    fint, energy = disc.forces(u, mat)
    for it in range(NEWTON_MAXIT + 1):
        r = (fext - fint)[free]
        scale = np.linalg.norm(fext) + np.linalg.norm(fint) + 1e-30
        rel = np.linalg.norm(r) / scale
        if not np.isfinite(rel):
            raise NotConverged("non-finite residual")
        if rel <= NEWTON_RTOL:
            return u, it
        if it == NEWTON_MAXIT:
            raise NotConverged(f"residual {rel:.1e} after {it} iterations")
        k = disc.tangent(u, mat)[free][:, free]
        du = solver.solve(k, r)
        potential = energy - fext @ u
        alpha = 1.0
        for _ in range(12):
            trial = u.copy()
            trial[free] += alpha * du
            if disc.min_volume_ratio(trial) > 0.0:
                t_fint, t_energy = disc.forces(trial, mat)
                # accept a decrease of the potential (or no increase beyond roundoff)
                if t_energy - fext @ trial <= potential + 1e-12 * (abs(potential) + abs(energy)):
                    break
            alpha *= 0.5
        else:
            raise NotConverged("line search failed")
        u, fint, energy = trial, t_fint, t_energy
        log.append((it, rel, alpha))
    raise AssertionError("unreachable")


def load_path(disc, mat, dirichlet, prescribed, fext_unit, targets, dt0, u_guess=None,
              lu=None):
    """Follows the load parameter t from 0 through each of `targets` (increasing), solving the
    static problem at every step: u[dirichlet] = prescribed * t, external load fext_unit * t.
    Adaptive steps: start at dt0, halve a failed step, grow by 1.5 after an easy one. The
    predictor extrapolates the last two converged states (or t * u_guess at the first step);
    `lu` may seed the linear solver's preconditioner. Returns ({target: u}, steps, newton iterations, factorisations)."""
    free = np.setdiff1d(np.arange(disc.ndofs), dirichlet)
    solver = TangentSolver(lu=lu)
    hist = [(0.0, np.zeros(disc.ndofs))]
    out, steps, iters, dt = {}, 0, 0, dt0
    for target in targets:
        while hist[-1][0] < target - 1e-12:
            t0, u0 = hist[-1]
            t1 = min(t0 + dt, target)
            if t1 > target - 1e-9 * target:
                t1 = target
            if len(hist) >= 2:
                tp, up = hist[-2]
                pred = u0 + (t1 - t0) / (t0 - tp) * (u0 - up)
            elif u_guess is not None:
                pred = t1 * u_guess
            else:
                pred = u0.copy()
            pred[dirichlet] = prescribed * t1
            log = []
            try:
                u1, n = newton(disc, mat, pred, free, fext_unit * t1, solver, log)
            except NotConverged:
                dt = (t1 - t0) / 2
                if dt < 1e-4 * max(targets):
                    raise
                continue
            steps, iters = steps + 1, iters + n
            hist = [hist[-1], (t1, u1)]
            if n <= 5:
                dt = 1.5 * (t1 - t0)
        out[target] = hist[-1][1]
    return out, steps, iters, solver.factorisations


def solve_linear(disc, k, dirichlet, prescribed, fext):
    """Linear solve K u = fext with u[dirichlet] = prescribed (m). Returns (u, LU of K_ff)."""
    free = np.setdiff1d(np.arange(disc.ndofs), dirichlet)
    u = np.zeros(disc.ndofs)
    u[dirichlet] = prescribed
    rhs = (fext - k @ u)[free]
    lu = factor(k[free][:, free])
    u[free] = lu.solve(rhs)
    return u, lu


# --------------------------------------------------------------------------------------
# Problems
# --------------------------------------------------------------------------------------

def cantilever(k, order, moduli=BEAM_MODULI):
    """Cantilever 0.16 x 0.04 x 0.04 m (4k x k x k cubes), clamped at x = 0, under rho g along
    -y. For each modulus: tip_mm = minus the mean y-displacement of the vertices of the face
    x = 0.16, mm (positive = sag), linear-elastic and Neo-Hookean. Yields result rows."""
    lx, ly, lz = BEAM
    disc = Discretisation(box(lx, ly, lz, 4 * k, k, k), order)
    clamp = disc.vb.get_dofs(lambda x: np.isclose(x[0], 0.0)).all()
    tip = disc.vertex_dofs(disc.face_vertices(0, lx), 1)
    fg = disc.gravity_load()
    # Linear elasticity: the stiffness is proportional to E, so one solve (at the first
    # modulus) serves all, u(E) = u(E0) E0 / E; its LU also preconditions the Newton solves.
    t = time.time()
    e0 = moduli[0][1]
    u_lin0, lu_lin = solve_linear(disc, disc.linear_stiffness(e0), clamp, 0.0, fg)
    t_lin = time.time() - t
    for label, young in moduli:
        u_lin = u_lin0 * (e0 / young)
        yield dict(problem="cantilever", quantity="tip_mm", case=f"E={label} linear",
                   element=f"P{order}", level=k, dofs=disc.ndofs,
                   value=-u_lin[tip].mean() * 1e3, time_s=t_lin if young == e0 else 0.0,
                   note="linear solve" if young == e0 else f"= E={moduli[0][0]} linear x E0/E")
        t = time.time()
        mat = snh_parameters(young)
        # small deflection: one step from the linear answer; large: from 1/4 of the weight
        dt0 = 1.0 if young >= 1e6 else 0.25
        try:
            sol, steps, iters, facts = load_path(disc, mat, clamp, 0.0, fg, [1.0], dt0, u_lin,
                                                 lu=lu_lin)
            value, note = -sol[1.0][tip].mean() * 1e3, f"{steps} steps, {iters} Newton its, {facts} LU"
        except NotConverged as e:
            value, note = float("nan"), f"did not converge: {e}"
        yield dict(problem="cantilever", quantity="tip_mm", case=f"E={label} snh",
                   element=f"P{order}", level=k, dofs=disc.ndofs, value=value,
                   time_s=time.time() - t, note=note)


def compress_problem(k, order):
    """The `compress` discretisation: (disc, dirichlet dofs, their prescribed values per unit
    strain, the top face's y dofs, the x dofs of the vertices on the face x = 0.04)."""
    disc = Discretisation(box(CUBE, CUBE, CUBE, k, k, k), order)
    dofs = disc.vb.get_dofs
    bottom = dofs(lambda x: np.isclose(x[1], 0.0)).all("u^2")
    top = dofs(lambda x: np.isclose(x[1], CUBE)).all("u^2")
    sym_x = dofs(lambda x: np.isclose(x[0], 0.0)).all("u^1")
    sym_z = dofs(lambda x: np.isclose(x[2], 0.0)).all("u^3")
    dirichlet = np.concatenate([bottom, top, sym_x, sym_z])
    prescribed = np.concatenate([np.zeros(len(bottom)), -CUBE * np.ones(len(top)),
                                 np.zeros(len(sym_x) + len(sym_z))])
    assert len(np.unique(dirichlet)) == len(dirichlet)
    side = disc.vertex_dofs(disc.face_vertices(0, CUBE), 0)
    return disc, dirichlet, prescribed, top, side


def compress(k, order, strains=STRAINS):
    """Cube of side 0.04 m (k^3 cubes), E = 2e5 Pa, no gravity, between frictionless plates:
    u_y = 0 on y = 0, u_y = -s 0.04 on y = 0.04, symmetry u_x = 0 on x = 0 and u_z = 0 on
    z = 0. force_n: total reaction on the top face (N, positive in compression) = minus the sum
    of the internal forces of its y dofs; bulge_mm: mean x-displacement of the vertices of the
    face x = 0.04, mm. The strain s is the load parameter, stepped through every s at once."""
    disc, dirichlet, prescribed, top, side = compress_problem(k, order)
    mat = snh_parameters(CUBE_E)
    t = time.time()
    try:
        sol, steps, iters, facts = load_path(disc, mat, dirichlet, prescribed,
                                             np.zeros(disc.ndofs), list(strains), 0.05)
        note = f"path: {steps} steps, {iters} Newton its, {facts} LU"
    except NotConverged as e:
        sol, note = {}, f"did not converge: {e}"
    elapsed = time.time() - t
    for s in strains:
        if s in sol:
            fint, _ = disc.forces(sol[s], mat)
            force, bulge = -fint[top].sum(), sol[s][side].mean() * 1e3
        else:
            force = bulge = float("nan")
        exact_force, exact_bulge = uniaxial_analytic(CUBE_E, s)
        for quantity, value, exact in (("force_n", force, exact_force),
                                       ("bulge_mm", bulge, exact_bulge)):
            yield dict(problem="compress", quantity=quantity, case=f"s={s:g}",
                       element=f"P{order}", level=k, dofs=disc.ndofs, value=value,
                       analytic=exact, time_s=elapsed, note=note)


def analytic_rows():
    """The exact answers of `compress`, as rows of element `analytic`."""
    for s in STRAINS:
        force, bulge = uniaxial_analytic(CUBE_E, s)
        for quantity, value in (("force_n", force), ("bulge_mm", bulge)):
            yield dict(problem="compress", quantity=quantity, case=f"s={s:g}",
                       element="analytic", level="", dofs="", value=value, time_s=0.0,
                       note="closed form, uniaxial stress")


# --------------------------------------------------------------------------------------
# Stability of the compression's homogeneous solution (--stability)
# --------------------------------------------------------------------------------------
# Past some strain a block squeezed between plates need not stay homogeneous: it can barrel,
# wrinkle or crease, and then the problem has more than one equilibrium. The homogeneous
# state stays an equilibrium of every mesh (it is a linear displacement field, which every
# element reproduces exactly), and the Newton path above, started homogeneous, never leaves
# it. It is a *stable* equilibrium only while the tangent stiffness restricted to the free
# dofs, K_ff (the Hessian of the energy there), is positive definite. --stability follows the
# homogeneous path through STABILITY_STRAINS and reports at each strain K_ff's smallest
# eigenvalue relative to its value at rest (1 at s = 0; negative: the homogeneous state is a
# saddle, the energy falls along a non-homogeneous mode, so a solver that is disturbed off it
# need not come back), the number of negative
# eigenvalues, where the unstable mode lives, and the strain where the smallest eigenvalue
# crosses zero (the first bifurcation), refined by regula falsi along the path.
#
# Plain eigenvalues of K_ff (not against the mass matrix): the magnitudes depend on that
# choice, the signs, the counts and the critical strain do not (Sylvester's law of inertia).
# The material itself never loses strong ellipticity: its acoustic tensor is
# mu I + lam' (cof F n)(cof F n)^T >= mu I for every F and direction n (the (J - gamma) term
# drops out), so a negative eigenvalue is an instability of the body and its free surfaces,
# not of the material.

STABILITY_STRAINS = tuple(round(0.05 * i, 2) for i in range(1, 15))    # 0.05, 0.1, ..., 0.7
STABILITY_MESHES = ((1, 1), (1, 2), (1, 4), (1, 8), (2, 1), (2, 2), (2, 4))   # (order, k)
STABILITY_FINE_MESHES = ((2, 8),)       # --stability --fine adds these (minutes, not seconds)
CRITICAL_STRAIN_TOL = 1e-4              # regula falsi stops when the bracket is this narrow
DENSE_CROSSCHECK_MAX = 2500             # free dofs up to which a dense eigensolve checks it


def inertia_factor(k):
    """Sparse LU of the symmetric matrix `k` with diagonal pivots only, so the row and column
    permutations agree and L U = P k P^T with U = D L^T: the signs of U's diagonal are the
    signs of k's eigenvalues (Sylvester's law of inertia). Returns (LU, negative count)."""
    lu = sla.splu(k.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                  options=dict(SymmetricMode=True))
    d = lu.U.diagonal()
    if not np.array_equal(lu.perm_r, lu.perm_c) or not np.all(np.isfinite(d)) or np.any(d == 0):
        raise RuntimeError("no symmetric LU with nonzero pivots: inertia unknown")
    return lu, int(np.sum(d < 0))


def smallest_eigenpair(k, guess, margin):
    """Smallest eigenvalue of the symmetric sparse matrix `k` and its unit eigenvector, by
    shift-invert Lanczos (ARPACK) about a shift sigma shown to lie below the whole spectrum
    (k - sigma I has no negative pivot), so that the eigenvalue nearest sigma is the smallest.
    sigma starts at min(guess, 0) * 1.25 - margin and moves down until that holds."""
    n = k.shape[0]
    eye = sp.identity(n, format="csc")
    sigma = 1.25 * min(guess, 0.0) - margin
    for _ in range(60):
        lu, negative = inertia_factor(k - sigma * eye)
        if negative == 0:
            break
        sigma = 2.0 * sigma - margin
    else:
        raise RuntimeError("found no shift below the spectrum")
    op = sla.LinearOperator((n, n), matvec=lu.solve, dtype=float)
    v0 = np.random.default_rng(0).standard_normal(n)
    w, v = sla.eigsh(k, k=1, sigma=sigma, which="LM", OPinv=op, v0=v0, tol=1e-13)
    lam, vec = float(w[0]), v[:, 0] / np.linalg.norm(v[:, 0])
    residual = np.linalg.norm(k @ vec - lam * vec)
    if not residual <= 1e-7 * (abs(lam) + margin):
        raise RuntimeError(f"eigenpair residual {residual:.1e} for eigenvalue {lam:.6g}")
    return lam, vec


def compress_stability(k, order, strains=STABILITY_STRAINS):
    """The `compress` problem's homogeneous path at level k, element P`order`: one row per
    strain (point=grid) and one for the critical strain (point=critical). Row fields:
    min_eig = smallest eigenvalue of K_ff (N/m), min_eig_rel = that / the same at rest,
    negative = number of negative eigenvalues of K_ff, surface_share = share of the smallest
    mode's squared amplitude on the free faces x = 0.04 and z = 0.04 (whose dofs are
    surface_dofs of the free dofs), force_rel_err = the plate force against the closed form
    (shows the path is the homogeneous one), dense_err = |min_eig - dense eigensolver| /
    rest value where a dense check was made."""
    disc, dirichlet, prescribed, top, _ = compress_problem(k, order)
    mat = snh_parameters(CUBE_E)
    free = np.setdiff1d(np.arange(disc.ndofs), dirichlet)
    loc = disc.vb.doflocs[:, free]
    on_face = np.isclose(loc[0], CUBE) | np.isclose(loc[2], CUBE)
    zero = np.zeros(disc.ndofs)
    k_rest = disc.tangent(zero, mat)[free][:, free]
    lam_rest, _ = smallest_eigenpair(k_rest, 0.0, 1e-9 * abs(k_rest.diagonal()).mean())
    base = dict(problem="compress", element=f"P{order}", level=k, free_dofs=len(free),
                surface_dofs=float(on_face.mean()))
    last = [lam_rest]

    def measure(s, u):
        kff = disc.tangent(u, mat)[free][:, free]
        lam, vec = smallest_eigenpair(kff, last[0], 0.25 * lam_rest)
        last[0] = lam
        negative = inertia_factor(kff)[1]
        dense_err = ""
        if len(free) <= DENSE_CROSSCHECK_MAX:
            w = np.linalg.eigvalsh(kff.toarray())
            dense_err = abs(lam - w[0]) / lam_rest
            if int(np.sum(w < 0)) != negative:
                raise RuntimeError(f"inertia {negative} but {int(np.sum(w < 0))} negative "
                                   "eigenvalues found densely")
        force = -disc.forces(u, mat)[0][top].sum()
        return dict(base, strain=s, min_eig=lam, min_eig_rel=lam / lam_rest, negative=negative,
                    surface_share=float(np.sum(vec[on_face] ** 2)),
                    force_rel_err=abs(force / uniaxial_analytic(CUBE_E, s)[0] - 1),
                    dense_err=dense_err)

    sol, steps, iters, facts = load_path(disc, mat, dirichlet, prescribed, zero,
                                         list(strains), 0.05)
    rows = []
    for s in strains:
        rows.append(dict(measure(s, sol[s]), point="grid"))
    # the first zero crossing of min_eig along the path, from the grid bracket by the Illinois
    # variant of regula falsi (each trial strain solved by Newton from the interpolated path)
    crossing = next((i for i, r in enumerate(rows) if r["min_eig"] <= 0.0), None)
    if crossing is None:
        critical = dict(base, strain="", point="critical",
                        note=f"stable up to s={strains[-1]:g}")
    else:
        if crossing == 0:
            lo = (0.0, zero, 1.0)
        else:
            lo = (strains[crossing - 1], sol[strains[crossing - 1]], rows[crossing - 1]["min_eig_rel"])
        hi = (strains[crossing], sol[strains[crossing]], rows[crossing]["min_eig_rel"])
        weight_lo = weight_hi = 1.0      # Illinois: halve the stale end's weight
        solver, side, trials, near = TangentSolver(), 0, 0, rows[crossing]
        while hi[0] - lo[0] > CRITICAL_STRAIN_TOL and trials < 40:
            f_lo, f_hi = weight_lo * lo[2], weight_hi * hi[2]
            s = hi[0] - f_hi * (hi[0] - lo[0]) / (f_hi - f_lo)
            s = min(max(s, lo[0] + 0.25 * CRITICAL_STRAIN_TOL), hi[0] - 0.25 * CRITICAL_STRAIN_TOL)
            pred = lo[1] + (s - lo[0]) / (hi[0] - lo[0]) * (hi[1] - lo[1])
            pred[dirichlet] = prescribed * s
            u, _ = newton(disc, mat, pred, free, zero, solver, [])
            r = measure(s, u)
            trials += 1
            if abs(r["min_eig_rel"]) < abs(near["min_eig_rel"]):
                near = r
            if r["min_eig"] > 0.0:
                lo, weight_lo = (s, u, r["min_eig_rel"]), 1.0
                weight_hi = weight_hi / 2 if side == +1 else 1.0
                side = +1
            else:
                hi, weight_hi = (s, u, r["min_eig_rel"]), 1.0
                weight_lo = weight_lo / 2 if side == -1 else 1.0
                side = -1
        s_c = lo[0] + lo[2] * (hi[0] - lo[0]) / (lo[2] - hi[2])
        critical = dict(near, strain=s_c, point="critical",
                        note=f"bracket [{lo[0]:.6f}, {hi[0]:.6f}] after {trials} trial strains; "
                             f"eigen data at the trial nearest zero (s={near['strain']:.6f})")
    rows.append(critical)
    note = f"path: {steps} steps, {iters} Newton its, {facts} LU"
    for r in rows:
        r.setdefault("note", note)
    return rows


STABILITY_COLS = ["problem", "element", "level", "free_dofs", "point", "strain", "min_eig",
                  "min_eig_rel", "negative", "surface_share", "surface_dofs", "force_rel_err",
                  "dense_err", "note"]


def stability_line(r):
    head = (f"RESULT reference.fem_stability problem={r['problem']} element={r['element']} "
            f"level={r['level']}")
    if r["point"] == "critical":
        if r["strain"] == "":
            return head + f" critical_strain=none ({r['note']})"
        return head + f" critical_strain={r['strain']:.4f}"
    return head + (f" strain={r['strain']:g} min_eig_rel={r['min_eig_rel']:.4f} "
                   f"negative={r['negative']} surface_share={r['surface_share']:.2f}")


def run_stability(fine):
    t0 = time.time()
    meshes = STABILITY_MESHES + (STABILITY_FINE_MESHES if fine else ())
    rows, lines = [], []
    for order, k in meshes:
        t = time.time()
        for r in compress_stability(k, order):
            rows.append(r)
            lines.append(stability_line(r))
            print(lines[-1], flush=True)
        print(f"# P{order} k={k}: {rows[-1]['note']}; {rows[-2]['note']}; "
              f"{time.time() - t:.1f} s", flush=True)
    OUT_DIR.mkdir(parents=True, exist_ok=True)
    with open(OUT_DIR / "stability.csv", "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(STABILITY_COLS)
        for r in rows:
            w.writerow([fmt(r.get(c, ""), 8) if c != "strain" or r["point"] == "critical"
                        else f"{r[c]:g}" for c in STABILITY_COLS])
    (OUT_DIR / "stability.txt").write_text("\n".join(lines) + "\n")
    worst_dense = max((r["dense_err"] for r in rows if r.get("dense_err", "") != ""),
                      default=0.0)
    worst_force = max(r["force_rel_err"] for r in rows if "force_rel_err" in r)
    print(f"# dense cross-check: max |min_eig - dense| / rest value {worst_dense:.1e}; "
          f"homogeneous path: max plate-force error vs closed form {worst_force:.1e}")
    print(f"wrote {OUT_DIR.relative_to(ROOT)}/stability.csv, stability.txt "
          f"in {time.time() - t0:.0f} s")
    return 0 if worst_dense <= 1e-8 and worst_force <= CHECK_RTOL else 1


# --------------------------------------------------------------------------------------
# Self-test of the numpy kernel against scikit-fem's own form assembly
# --------------------------------------------------------------------------------------

def kernel_selftest():
    """Checks Discretisation.forces/.tangent on a 2x1x1 P2 mesh under a random finite
    displacement against the same integrals written as scikit-fem forms (cof F = J F^-T via
    skfem.helpers, d cof[H] = J ((F^-T : H) F^-T - F^-T H^T F^-T)), the tangent at rest
    against scikit-fem's linear_elasticity, and the tangent against finite differences of the
    force. Returns the largest relative discrepancy of each."""
    mat = mu, lam_p, gamma = snh_parameters(1e5)
    disc = Discretisation(box(0.08, 0.04, 0.04, 2, 1, 1), 2)
    rng = np.random.default_rng(7)
    # a smooth large deformation (stretch, shear, bending: det F from ~0.8 to ~1.3) plus noise
    u = disc.vb.project(lambda x: np.stack([0.1 * x[0] + 0.15 * x[1],
                                            -2.5 * x[0] ** 2 + 0.05 * x[2],
                                            0.2 * x[2] - 0.1 * x[0] * x[1] / 0.04]))
    u += 2e-4 * rng.standard_normal(disc.ndofs)
    j = det(disc.deformation_gradient(u))
    assert j.min() > 0.5 and j.max() - j.min() > 0.2, (j.min(), j.max())

    def mm(a, b):
        return np.einsum("ik...,kj...->ij...", a, b)

    def piola(f):
        j = det(f)
        return mu * f + lam_p * (j - gamma) * j * transpose(inv(f))

    @LinearForm
    def force_form(v, w):
        return ddot(piola(grad(w["u"]) + np.eye(3)[:, :, None, None]), grad(v))

    @BilinearForm
    def tangent_form(du, v, w):
        f = grad(w["u"]) + np.eye(3)[:, :, None, None]
        j, fit, h = det(f), transpose(inv(f)), grad(du)
        dcof = j * (ddot(fit, h) * fit - mm(mm(fit, transpose(h)), fit))
        dp = mu * h + lam_p * ddot(j * fit, h) * j * fit + lam_p * (j - gamma) * dcof
        return ddot(dp, grad(v))

    uw = disc.vb.interpolate(u)
    f_ref = asm(force_form, disc.vb, u=uw)
    k_ref = asm(tangent_form, disc.vb, u=uw)
    f_ker, _ = disc.forces(u, mat)
    k_ker = disc.tangent(u, mat)
    err_f = np.abs(f_ker - f_ref).max() / np.abs(f_ref).max()
    err_k = abs(k_ker - k_ref).max() / abs(k_ref).max()
    k_lin = disc.linear_stiffness(1e5)
    err_rest = abs(disc.tangent(np.zeros(disc.ndofs), mat) - k_lin).max() / abs(k_lin).max()
    d = 1e-7 * rng.standard_normal(disc.ndofs)
    fd = (disc.forces(u + d, mat)[0] - disc.forces(u - d, mat)[0]) / 2
    err_fd = np.abs(fd - k_ker @ d).max() / np.abs(k_ker @ d).max()
    return dict(force_vs_skfem=err_f, tangent_vs_skfem=err_k, rest_vs_linear=err_rest,
                tangent_vs_fd=err_fd)


# --------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------

def fmt(x, digits=7):
    return "" if x == "" or x is None else (f"{x:.{digits}g}" if isinstance(x, float) else str(x))


def add_changes(rows):
    """change_pct: relative change (%) from the previous level of the same series."""
    last = {}
    for r in rows:
        key = (r["problem"], r["quantity"], r["case"], r["element"])
        prev = last.get(key)
        ok = prev is not None and math.isfinite(prev) and prev != 0 and math.isfinite(r["value"])
        r["change_pct"] = 100.0 * (r["value"] - prev) / abs(prev) if ok else ""
        if r["element"] != "analytic":
            last[key] = r["value"]


def result_line(r):
    case = f'"{r["case"]}"' if " " in r["case"] else r["case"]
    line = (f"FEM problem={r['problem']} quantity={r['quantity']} case={case} "
            f"element={r['element']} level={r['level']} value={fmt(r['value'], 9)} "
            f"change_pct={fmt(r['change_pct'], 4)}")
    if "analytic" in r and math.isfinite(r["value"]):
        line += f" rel_err_vs_analytic={abs(r['value'] / r['analytic'] - 1):.1e}"
    return line + f" dofs={r['dofs']} time_s={r['time_s']:.1f}"


def versions():
    return {"python": sys.version.split()[0], "scikit-fem": skfem.__version__,
            "numpy": np.__version__, "scipy": scipy.__version__}


def write_outputs(rows, selftest, wall_s):
    OUT_DIR.mkdir(parents=True, exist_ok=True)
    cols = ["problem", "quantity", "case", "element", "level", "dofs", "value", "change_pct"]
    with open(OUT_DIR / "fem.csv", "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(cols)
        for r in rows:
            w.writerow([fmt(r[c], 10) if c == "value" else fmt(r[c], 4) for c in cols])

    # answers: the finest P2 level of each series (what our own solver is compared with)
    answers = {}
    for r in rows:
        if r["element"] == "P2":
            answers.setdefault(r["problem"], {}).setdefault(r["quantity"], {})[r["case"]] = {
                "value": float(r["value"]), "level": int(r["level"]), "dofs": int(r["dofs"]),
                "change_pct": float(r["change_pct"]) if r["change_pct"] != "" else None,
                "converged": bool(r["change_pct"] != "" and
                                  abs(r["change_pct"]) <= CONVERGED_PCT)}
    # Aitken extrapolation from the three finest P2 levels (levels doubling): an estimate of
    # the mesh-converged value, v_inf = v3 + (v3 - v2) / (q - 1), q = (v2 - v1) / (v3 - v2).
    p2 = {}
    for r in rows:
        if r["element"] == "P2":
            p2.setdefault((r["problem"], r["quantity"], r["case"]), []).append(r["value"])
    for (prob, q, case), v in p2.items():
        if len(v) >= 3 and v[-1] != v[-2] and v[-2] != v[-3]:
            ratio = (v[-2] - v[-3]) / (v[-1] - v[-2])
            if ratio > 1.5:   # only for a clean monotone convergence
                answers[prob][q][case]["extrapolated"] = float(v[-1] + (v[-1] - v[-2]) /
                                                                (ratio - 1))
    for r in rows:
        if r["element"] == "analytic":
            a = answers["compress"][r["quantity"]][r["case"]]
            a["analytic"] = float(r["value"])
            a["rel_err_vs_analytic"] = abs(a["value"] / a["analytic"] - 1)
    meta = {"generated_by": "scripts/fem-reference --all", "element": "P2 (quadratic tets)",
            "units": {"tip_mm": "mm", "force_n": "N", "bulge_mm": "mm"},
            "material": "stable Neo-Hookean (snh) / linear elasticity, nu = 0.4",
            "versions": versions()}
    with open(OUT_DIR / "answers.json", "w") as fh:
        json.dump({"meta": meta, **answers}, fh, indent=2)
        fh.write("\n")

    v = versions()
    md = [
        "# Finite-element reference (scikit-fem)",
        "",
        f"Generated by `scripts/fem-reference --all` on a 2-core machine in {wall_s:.0f} s "
        f"(scikit-fem {v['scikit-fem']}, numpy {v['numpy']}, scipy {v['scipy']}, "
        f"Python {v['python']}). Do not edit by hand; the code and its description are in "
        "`scripts/fem/reference.py`.",
        "",
        "Static solutions of the stable Neo-Hookean material of our solver (`snh`: "
        "Ψ = μ/2 (I_C − 3) + λ'/2 (J − γ)² − λ'/2 (1 − γ)², λ' = λ + μ, γ = 1 + μ/λ', "
        "ν = 0.4) and of linear elasticity (`linear`, scikit-fem's `linear_elasticity`), "
        "total Lagrangian, Newton with load stepping, on `MeshTet.init_tensor` meshes (six tets "
        "per cube) with linear (P1) and quadratic (P2) tets. `answers.json` holds the finest P2 "
        "level of each series: the answer our solver is compared with.",
        "",
        "- **cantilever**: 0.16 × 0.04 × 0.04 m, clamped at x = 0, own weight (ρ = 1000 kg/m³, "
        "g = 9.81 m/s² along −y); level k = 4k × k × k cubes; `tip_mm` = minus the mean "
        "y-displacement of the mesh vertices on the face x = 0.16 (mm, positive = sag).",
        "- **compress**: cube of side 0.04 m, E = 200 kPa, between frictionless plates "
        "(u_y = 0 at y = 0, u_y = −s·0.04 at y = 0.04, symmetry u_x = 0 at x = 0 and u_z = 0 at "
        "z = 0); level k = k³ cubes; `force_n` = reaction on the top face (N, compression "
        "positive), `bulge_mm` = mean x-displacement of the vertices on x = 0.04 (mm). "
        "Homogeneous uniaxial stress: every mesh must reproduce the closed-form answer.",
        "",
        f"Kernel self-test (numpy force/tangent vs scikit-fem forms, max relative difference): "
        + ", ".join(f"{k} {e:.1e}" for k, e in selftest.items()) + ".",
        "",
    ]
    # convergence at a glance: the cantilever's levels side by side, and the compression's
    # worst disagreement with the closed form over every mesh and element
    levels = sorted({r["level"] for r in rows if r["problem"] == "cantilever"})
    md += ["## Cantilever tip sag (mm) by level k; change % to the previous level", "",
           "| case | element | " + " | ".join(f"k = {k}" for k in levels) + " |",
           "|---|---|" + "---|" * len(levels)]
    series = {}
    for r in rows:
        if r["problem"] == "cantilever":
            series.setdefault((r["case"], r["element"]), {})[r["level"]] = r
    for (case, element), by_level in sorted(series.items(), key=lambda x: x[0][1]):
        cells = []
        for k in levels:
            r = by_level.get(k)
            cells.append("" if r is None else fmt(r["value"], 5) + (
                f" ({r['change_pct']:+.2f} %)" if r["change_pct"] != "" else ""))
        md.append(f"| {case} | {element} | " + " | ".join(cells) + " |")
    md += ["", "## Compression: FEM against the closed form", "",
           "| case | quantity | analytic | FEM (P2, finest) | worst relative error, "
           "all levels, P1 and P2 |", "|---|---|---|---|---|"]
    for s in STRAINS:
        for q in ("force_n", "bulge_mm"):
            fem = [r for r in rows if r["problem"] == "compress" and r["quantity"] == q
                   and r["case"] == f"s={s:g}" and r["element"] != "analytic"]
            worst = max(abs(r["value"] / r["analytic"] - 1) for r in fem)
            fine = [r for r in fem if r["element"] == "P2"][-1]
            md.append(f"| s={s:g} | {q} | {fine['analytic']:.9g} | {fine['value']:.9g} | "
                      f"{worst:.1e} |")
    md += [
        "",
        "## Every result",
        "",
        "| problem | quantity | case | element | level | dofs | value | change % | "
        "vs analytic | time s | solver |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        rel = (f"{abs(r['value'] / r['analytic'] - 1):.1e}"
               if "analytic" in r and math.isfinite(r["value"]) else "")
        md.append(f"| {r['problem']} | {r['quantity']} | {r['case']} | {r['element']} | "
                  f"{r['level']} | {r['dofs']} | {fmt(r['value'], 6)} | "
                  f"{fmt(r['change_pct'], 3)} | {rel} | {r['time_s']:.1f} | {r['note']} |")
    md += ["", "## Answers (`answers.json`): the finest P2 level", "",
           "Converged = change between the two finest P2 levels ≤ 1 %.", ""]
    for prob, qs in answers.items():
        for q, cases in qs.items():
            for case, a in cases.items():
                extra = f", analytic {a['analytic']:.6g}" if "analytic" in a else ""
                if "extrapolated" in a:
                    extra += f", Aitken-extrapolated from the 3 P2 levels {a['extrapolated']:.6g}"
                md.append(f"- {prob} {q} {case}: {a['value']:.6g} at level {a['level']} "
                          f"(change {fmt(a['change_pct'], 3)} %{extra}) — "
                          f"{'converged' if a['converged'] else 'NOT converged'}")
    (OUT_DIR / "fem.md").write_text("\n".join(md) + "\n")


# --------------------------------------------------------------------------------------
# Modes
# --------------------------------------------------------------------------------------

def run_all():
    t0 = time.time()
    selftest = kernel_selftest()
    print("FEM selftest " + " ".join(f"{k}={e:.1e}" for k, e in selftest.items()), flush=True)
    rows = []
    for order in (1, 2):
        for k in BEAM_LEVELS:
            rows += list(cantilever(k, order))
    for order in (1, 2):
        for k in CUBE_LEVELS:
            rows += list(compress(k, order))
    rows += list(analytic_rows())
    add_changes(rows)
    for r in rows:
        print(result_line(r), flush=True)
    write_outputs(rows, selftest, time.time() - t0)
    print(f"wrote {OUT_DIR.relative_to(ROOT)}/fem.csv, fem.md, answers.json "
          f"in {time.time() - t0:.0f} s")
    bad = [r for r in rows if not (isinstance(r["value"], float) and math.isfinite(r["value"]))]
    return 1 if bad else 0


def check_values():
    """The --check set: cantilever k = 2 P2 (both moduli), compress k = 1 P2 (every strain)."""
    rows = list(cantilever(2, 2)) + list(compress(1, 2))
    return {f"{r['problem']} {r['quantity']} {r['case']} {r['element']} k={r['level']}": r
            for r in rows}


def run_check(bless):
    t0 = time.time()
    failures = []
    selftest = kernel_selftest()
    for name, err in selftest.items():
        if not err < 1e-6:
            failures.append(f"kernel self-test {name}: relative difference {err:.1e} > 1e-6")
    values = check_values()
    if bless:
        blessed = {"versions": versions(),
                   "values": {k: float(r["value"]) for k, r in values.items()}}
        CHECK_FILE.write_text(json.dumps(blessed, indent=2) + "\n")
        print(f"blessed {len(values)} values into {CHECK_FILE.relative_to(ROOT)}")
        return 0
    committed = json.loads(CHECK_FILE.read_text())["values"]
    for key in sorted(set(committed) - set(values)):
        failures.append(f"{key}: in check.json but not computed")
    per_problem = {}
    for key, r in values.items():
        want = committed.get(key)
        got = float(r["value"])
        if want is None:
            failures.append(f"{key}: computed {got!r} but not in check.json (re-bless?)")
            continue
        rel = abs(got - want) / max(abs(want), 1e-300)
        if not rel <= CHECK_RTOL:
            failures.append(f"{key}: got {got!r}, check.json has {want!r} (relative {rel:.1e})")
        if "analytic" in r:
            rel_a = abs(got / r["analytic"] - 1)
            if not rel_a <= CHECK_RTOL:
                failures.append(f"{key}: {got!r} differs from the analytic {float(r['analytic'])!r} "
                                f"by {rel_a:.1e} relative")
        p = per_problem.setdefault(r["problem"], [0, 0.0, 0.0])
        p[0] += 1
        p[1] = max(p[1], rel)
        if "analytic" in r:
            p[2] = max(p[2], rel_a)
    for msg in failures:
        print(f"FEM CHECK FAIL {msg}")
    for prob, (n, worst, worst_a) in per_problem.items():
        extra = f" max_rel_vs_analytic={worst_a:.1e}" if prob == "compress" else ""
        print(f"FEM CHECK {prob} values={n} max_rel_vs_committed={worst:.1e}{extra} "
              f"{'ok' if not any(f.startswith(prob) for f in failures) else 'FAILED'}")
    print(f"FEM CHECK selftest " + " ".join(f"{k}={e:.1e}" for k, e in selftest.items()))
    print(f"FEM CHECK {'FAILED' if failures else 'ok'} in {time.time() - t0:.1f} s")
    return 1 if failures else 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    mode = ap.add_mutually_exclusive_group(required=True)
    mode.add_argument("--all", action="store_true", help="every problem at every level")
    mode.add_argument("--check", action="store_true", help="small levels vs check.json")
    mode.add_argument("--bless", action="store_true", help="rewrite check.json")
    mode.add_argument("--stability", action="store_true",
                      help="smallest tangent eigenvalue along the compression's homogeneous path")
    ap.add_argument("--fine", action="store_true",
                    help="with --stability: also P2 at level 8 (a few minutes more)")
    args = ap.parse_args()
    if args.fine and not args.stability:
        ap.error("--fine only goes with --stability")
    for name, pin in PINS.items():
        have = versions()[name]
        if have != pin:
            print(f"warning: {name} {have} is not the pinned {pin}", file=sys.stderr)
    if args.all:
        return run_all()
    if args.stability:
        return run_stability(args.fine)
    return run_check(bless=args.bless)


if __name__ == "__main__":
    sys.exit(main())
