#!/usr/bin/env python3
"""Independent finite-element reference for the soft-body solver (static hyperelasticity).

What: static solutions of three small problems -- a cantilever sagging under its own weight,
a block squeezed between frictionless plates and (--indent) a slab indented by a rigid
frictionless sphere, against Hertz -- and of our bunny lattice under its own weight
(--bunny), computed with scikit-fem (a finite-element
library nobody in this project wrote) for the *same* material model our own solver uses: the
stable Neo-Hookean energy of Smith et al. 2018 in the form of Macklin & Mueller 2021 (see
softbody/src/methods/pbd/neohookean.rs, energy_density, and softbody/src/methods/reference.rs,
our XPBD accuracy reference). Our XPBD reference is compared with these numbers; this file
never reads anything from our solver, except --bunny, which reads the problem and our answer
from a file our side exports (the FEM solve itself uses only the problem).

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
                                    scripts/fem/check.json (relative 1e-6; the indentation at
                                    P1 and P2 k = 4, d = 1 mm among them) and the compression
                                    against its analytic answer, and checks that box() is our
                                    side's lattice; exit 1 on any mismatch
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
    scripts/fem-reference --bunny FILE [FILE...]
                                    our bunny against the FEM (below); writes
                                    docs/results/methods/fem/{bunny.csv,bunny.txt}
                                    (RESULT reference.fem problem=bunny lines); leaves the
                                    other outputs alone. The 10 % lattice takes ~3 min and
                                    3-4 GB at its peak (P2_refined, 67k dofs); on the 5 %
                                    one P1_refined takes ~70 s and P2 (55k dofs) over 5 min
    scripts/fem-reference --indent  the slab indented by a sphere (section "Indentation"):
                                    force against depth d = 0.25 ... 4 mm, stable Neo-Hookean
                                    and linear, P1 k = 6, 12, 24 and P2 k = 6, 12 (~3 min, 2 GB);
                                    writes docs/results/methods/fem/{indent.csv,indent.txt}
                                    (RESULT reference.fem problem=indent lines) and puts the
                                    finest P2 answers into answers.json (--all keeps them);
                                    leaves the other outputs alone

--bunny: a problem exported by our side (JSON, made by the Rust code, read as given): the
bunny as our reference solves it -- a fictitious-domain tet lattice (`nodes` [[x, y, z]] m,
`tets` [[a, b, c, d]] 0-based), each tet with a `weight` w in (0, 1], the fraction of it inside
the bunny's surface, that scales both its stiffness (E w with the same nu: mu w, lam' w, gamma
unchanged) and its density (rho w); the base (`fixed` nodes: y <= min y + 8 % of the height)
held at u = 0; the full own weight (`young_pa`, `nu`, `density_kg_m3`, `gravity` from the
file); and `ours` [[ux, uy, uz]], our static displacement of every node (m; `ours_steps`,
`ours_budget`: how it was reached). The FEM solves the same static problem (stable
Neo-Hookean, total Lagrangian, Newton with load stepping from the linear-elastic answer) at
the levels, in order of accuracy: P1 on the mesh (our discretisation: the like-for-like
comparison), P1 on the mesh refined once by scikit-fem (each tet into eight, each child
keeping its parent's weight; parents found by locating each child's centroid, checked), P2 on
the mesh, and P2 on the refined mesh -- a level with more than BUNNY_MAX_DOFS (150k) dofs is
skipped (P2_refined of the 5 % lattice: 404k dofs). The refinements keep the weighted lattice
as it is, so they measure how far the FEM on this lattice is from converged, not the
geometry's error. Tets hanging from the rest by one edge or vertex (hinges: a mechanism, whose
static answer is a rigid swing, not elasticity; the 5 % lattice has one, w = 0.02) are left
out of the FEM and their free nodes out of every statistic, ours included (bunny_solid). Fixed: every dof located at y <= cut (cut = the largest y of the fixed
nodes + 1e-9), the midside dofs on the base included. Per file and level, at the mesh's own
nodes (vertex dofs): fem_max_mm / fem_mean_mm = largest / mean |u| over all nodes (fixed ones
included); fem_change_pct / fem_mean_change_pct = their change from the previous level (%);
ours_max_mm / ours_mean_mm the same of `ours`; field_rms_pct = 100 RMS over nodes of
|u_ours - u_fem| / the FEM's largest |u|; material_field_rms_pct = the same over material nodes
(a node of at least one tet with w >= 0.5; the others, fringe nodes, touch only tets mostly
outside the surface: fictitious material); interior_field_rms_pct = over nodes all of whose
tets have w >= 0.99; field_max_err_pct = the largest |u_ours - u_fem| / the FEM's largest |u|.

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
import scipy.sparse.csgraph
import scipy.spatial
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

    def __init__(self, mesh, order, intorder=None):
        self.mesh = mesh
        self.order = order
        elem = ElementTetP1() if order == 1 else ElementTetP2()
        # default quadrature: degree 2 for P1 (F constant per tet), degree 4 (11 points) for P2;
        # `intorder` another degree (1 for P1: one point, exact, as F is constant per tet)
        self.vb = Basis(mesh, ElementVector(elem),
                        **({} if intorder is None else dict(intorder=intorder)))
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
        self.lu = None        # free the old factorisation before making the new one (peak memory)
        self.lu = factor(k)
        self.factorisations += 1
        return self.lu.solve(r)


class NotConverged(RuntimeError):
    pass


def line_minimum(disc, mat, u, du, free, fext, slope0, bound):
    """The line search of a contact problem (newton(..., line_min=True)): the step alpha along
    du (Newton's direction from u; slope0 = phi'(0) < 0, phi(alpha) the potential at
    u + alpha du). The full step if the potential falls there (to at most `bound`, the
    potential at u plus roundoff) or if phi'(1) <= |phi'(0)| / 2 (then it fell: for a quadratic
    phi, phi(1) < phi(0) exactly when phi'(1) < |phi'(0)|; the test on forces still works near
    convergence, where the fall is below the potential's rounding); else an approximate
    minimum of phi on [0, 1]: Illinois regula falsi on phi'(alpha) = (f_int - fext) . du until
    |phi'| <= 0.1 |phi'(0)|. Plain backtracking stalls when the step pushes a node that is not
    yet in contact (so the tangent does not know it) deep into the obstacle: the potential then
    falls only for alpha below about the node's clearance over its step, tiny for a node about
    to touch; the minimum along the line lets it in with about the right force, and the next
    tangent has it. Returns (alpha, u + alpha du, its f_int, its energy); raises NotConverged."""

    def at(alpha):
        trial = u.copy()
        trial[free] += alpha * du
        if disc.min_volume_ratio(trial) <= 0.0:
            return None
        fint, energy = disc.forces(trial, mat)
        return (alpha, trial, fint, energy), energy - fext @ trial, (fint - fext)[free] @ du

    hi = 1.0
    for _ in range(40):
        end = at(hi)
        if end is not None:
            break
        hi *= 0.5
    else:
        raise NotConverged("line search: inverted along the whole step")
    if end[1] <= bound or end[2] <= 0.5 * abs(slope0):
        return end[0]
    if not slope0 < 0.0:
        raise NotConverged(f"line search: not a descent direction (slope {slope0:.1e})")
    lo, slope_lo, slope_hi, side, below = 0.0, slope0, end[2], 0, None
    for _ in range(60):
        alpha = hi - slope_hi * (hi - lo) / (slope_hi - slope_lo)
        alpha = min(max(alpha, lo + 1e-6 * (hi - lo)), hi - 1e-6 * (hi - lo))
        point = at(alpha)
        if point is None:                     # inverted inside the bracket: bisect below it
            hi, side = 0.5 * (lo + alpha), 0
            continue
        if abs(point[2]) <= 0.1 * abs(slope0):
            return point[0]
        if point[2] < 0.0:
            lo, slope_lo, below = alpha, point[2], point
            slope_hi = slope_hi / 2 if side == -1 else slope_hi
            side = -1
        else:
            hi, slope_hi = alpha, point[2]
            slope_lo = slope_lo / 2 if side == +1 else slope_lo
            side = +1
        if hi - lo <= 1e-12:
            break
    if below is None:
        raise NotConverged("line search failed")
    return below[0]                           # the furthest point where phi still fell


def newton(disc, mat, u, free, fext, solver, log, line_min=False):
    """Newton's method from `u` (prescribed dofs already set) for f_int(u) = fext on the free
    dofs, with a backtracking line search on the potential energy (line_min: line_minimum's
    search instead, for contact). Returns (u, iterations).
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
        if line_min:
            alpha, trial, t_fint, t_energy = line_minimum(
                disc, mat, u, du, free, fext, -(r @ du),
                potential + 1e-12 * (abs(potential) + abs(energy)))
            u, fint, energy = trial, t_fint, t_energy
            log.append((it, rel, alpha))
            continue
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
    lu = None                 # the solver holds it, and drops it when it refactors
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
# Indentation (--indent): a slab pressed by a rigid frictionless sphere, against Hertz
# --------------------------------------------------------------------------------------
# A quarter of a block (symmetry planes x = 0 and z = 0: the block is 2 SLAB wide and SLAB
# thick), its base y = 0 clamped, no gravity, indented at the corner x = z = 0 of its top face
# by a rigid frictionless sphere of radius R whose centre moves down the y axis,
# c = (0, SLAB + R - d, 0), through the depths d (displacement control). Contact is nodal: no
# node (every vertex, and for P2 every edge midpoint) may be inside the sphere, frictionless.
# The mesh is box(), which is our side's lattice (box_is_ours, checked by --check and
# --indent), so P1 here is our discretisation node for node.
#
# Contact by an augmented Lagrangian: per node the energy max(0, lambda + k_c g)^2 / (2 k_c),
# g = R - |x - c| the penetration, lambda >= 0 the node's contact force from the last update
# (a penalty of stiffness k_c = CONTACT_STIFFNESS when lambda = 0), with its exact gradient and
# Hessian, so Newton settles the active set itself (the energy is C1 and piecewise smooth; the
# line search, line_minimum, lets a node that the step pushes into the sphere in with about the
# right force). At each depth the sphere is moved there in one load step (halved if Newton
# fails), then lambda <- max(0, lambda + k_c g) and Newton again, until no node is more than
# CONTACT_TOL d inside or outside the sphere while pushed by it: the exact nodal constraint,
# to that tolerance (the largest |g| / d is reported per row: gap_rel). The sphere's reaction
# is the sum of the contact forces' y components, times 4 (the whole sphere), checked against
# the clamped base's reaction (the body's equilibrium: base_rel). Linear systems: one sparse LU
# (SuperLU in a nested-dissection order, OrderedLU) serves many Newton steps (ContactSolver:
# the contact's changes by the Woodbury identity, the rest by GMRES); P1 with one quadrature
# point (exact: F is constant per tet), P2 with the default 11.
#
# Hertz (a rigid paraboloid on an elastic half-space): F = 4/3 E/(1 - nu^2) sqrt(R) d^(3/2),
# a = sqrt(R d). What separates this slab from it, estimated in closed form per row:
#   - the sphere is not a paraboloid (Sneddon's rigid sphere on a half-space, exact in linear
#     elasticity: d = a/2 ln((R + a)/(R - a)), F = E/(1 - nu^2)/2 ((a^2 + R^2) ln((R + a)/(R - a))
#     - 2 a R): 0.25 % under Hertz at d = 0.25 mm, 4 % at 4 mm;
#   - the slab is SLAB thick on a clamped base, not a half-space: Dimitriadis et al. 2002
#     (Biophys. J. 82, 2798, eq. 13: a layer of thickness h bonded to a rigid base,
#     chi = sqrt(R d)/h) multiply Hertz by 1 - 2 alpha0/pi chi + 4 alpha0^2/pi^2 chi^2
#     - 8/pi^3 (alpha0^3 + 4 pi^2/15 beta0) chi^3 + O(chi^4),
#     alpha0 = -(1.2876 - 1.4678 nu + 1.3442 nu^2)/(1 - nu),
#     beta0 = (0.6387 - 1.0277 nu + 1.5164 nu^2)/(1 - nu): +5.4 % at d = 0.25 mm, +25 % at 4 mm
#     (for a laterally infinite layer; this block's free sides, SLAB from the axis, soften it);
#   - finite strain (snh against linear), and the nodal contact itself: the contact patch is a
#     few nodes wide (at d = 0.25 mm, a = 1.6 mm against a node spacing of 1.25 mm on the
#     finest meshes here), a discretisation error that only refinement removes.

SLAB = 0.03                 # the quarter block's side, m (x, y, z in [0, SLAB])
SLAB_E = 1e5                # Young's modulus, Pa
INDENTER_R = 0.01           # the sphere's radius, m
INDENT_DEPTHS_MM = (0.25, 0.5, 1.0, 2.0, 4.0)
# (element order, cells per SLAB edge), in order of accuracy within each element; P1 k = 6 and
# 12 are our side's meshes
INDENT_LEVELS = ((1, 6), (1, 12), (1, 24), (2, 6), (2, 12))
INDENT_LAWS = ("snh", "linear")
# Penalty stiffness per node, N/m (200-800 x a node's elastic stiffness ~E h at k = 24 .. 6:
# each multiplier update cuts the penetration that much). Much stiffer is worse, not better:
# the residual's rounding floor is k_c times the rounding of |x - c| (~1e-18 m), and Newton's
# tolerance (NEWTON_RTOL of the force scale, ~1e-12 N at d = 0.25 mm) is below it at 1e7.
CONTACT_STIFFNESS = 1e5
CONTACT_TOL = 1e-6          # multiplier updates until every contact node's |g| <= this x d
CONTACT_UPDATES = 10        # at most this many updates per depth
INDENT_CHECK = ((1, 4), (2, 4))     # --check: these levels, snh, straight to d = 1 mm
INDENT_CHECK_DEPTH_MM = 1.0
CONTACT_GMRES_RTOL = 1e-7   # ContactSolver's GMRES stops at this preconditioned residual
TANGENT_REUSE = 0.01        # SphereContact reuses the body's tangent within this (see there)
CONTACT_CHANGE = 1e-2       # ContactSolver: a contact Hessian change this x k_c is "large"
CONTACT_COLUMNS = 48        # ContactSolver: new Woodbury columns a direct solve may cost


class LinearBody:
    """Linear elasticity on a Discretisation (scikit-fem's linear_elasticity stiffness K for
    (E, nu)) with the interface newton() uses: internal forces K u, energy u.K u / 2, tangent
    K, and no inversion test (a linear material has none)."""

    def __init__(self, disc, young_pa):
        self.vb, self.order, self.ndofs = disc.vb, disc.order, disc.ndofs
        self.k = disc.linear_stiffness(young_pa).tocsr()

    def forces(self, u, mat):
        f = self.k @ u
        return f, 0.5 * float(u @ f)

    def tangent(self, u, mat):
        return self.k

    def min_volume_ratio(self, u):
        return 1.0


class SphereContact:
    """A body (Discretisation or LinearBody) whose nodes are kept out of a rigid frictionless
    sphere of `radius` (augmented Lagrangian, module comment above): the body's interface for
    newton() (forces, tangent, min_volume_ratio, ndofs) with the contact energy
    max(0, lambda + k g)^2 / (2 k) per node added, g = radius - |x - c|, x = rest + u,
    k = `stiffness`, lambda = `multiplier` (N, per node; zero: a plain penalty). The nodes are
    every vertex and, for P2, every edge midpoint (every dof of the space is nodal)."""

    def __init__(self, body, radius, stiffness):
        self.body, self.radius, self.stiffness = body, radius, stiffness
        self.ndofs = body.ndofs
        vb = body.vb
        self.node_dofs = np.hstack([vb.nodal_dofs] + ([vb.edge_dofs] if body.order == 2 else []))
        assert self.node_dofs.shape[0] == 3 and len(np.unique(self.node_dofs)) == self.ndofs
        self.rest = vb.doflocs[:, self.node_dofs[0]].T.copy()      # (n_nodes, 3), m
        for i in (1, 2):
            assert np.array_equal(vb.doflocs[:, self.node_dofs[i]].T, self.rest)
        self.multiplier = np.zeros(len(self.rest))
        self._body_tangent = None
        self.set_centre(np.zeros(3))

    def set_centre(self, centre):
        """Moves the sphere's centre to `centre` (m)."""
        self.centre = np.asarray(centre, dtype=float)
        self._offset = self.rest - self.centre

    def contact(self, u):
        """The nodes the sphere pushes at displacement u: (their indices, contact forces
        p = lambda + k g > 0 (N), unit outward normals (x - c)/|x - c|, distances |x - c|,
        penetrations g = radius - |x - c| (m))."""
        v = self._offset + u[self.node_dofs].T
        r = np.linalg.norm(v, axis=1)
        g = self.radius - r
        p = self.multiplier + self.stiffness * g
        active = np.nonzero(p > 0.0)[0]
        return active, p[active], v[active] / r[active, None], r[active], g[active]

    def forces(self, u, mat):
        fint, energy = self.body.forces(u, mat)
        active, p, n, _, _ = self.contact(u)
        # the contact energy's gradient -p n (the sphere pushes the node along +n); dofs unique
        fint[self.node_dofs[:, active].T] -= p[:, None] * n
        return fint, energy + float(p @ p) / (2.0 * self.stiffness)

    def tangent(self, u, mat):
        # the body's tangent is reused while u stays within TANGENT_REUSE of where it was
        # assembled (relative to its largest displacement): an inexact Newton, whose steps
        # that only let a node into contact (tiny alpha) then cost no assembly
        if (self._body_tangent is None or np.abs(u - self._body_tangent[0]).max()
                > TANGENT_REUSE * np.abs(self._body_tangent[0]).max()):
            self._body_tangent = (u.copy(), self.body.tangent(u, mat))
        k = self._body_tangent[1]
        active, p, n, r, _ = self.contact(u)
        # Hessian of max(0, lambda + k g)^2 / (2 k), g = R - r: k n n^T - p (I - n n^T) / r
        nn = n[:, :, None] * n[:, None, :]
        h = self.stiffness * nn - (p / r)[:, None, None] * (np.eye(3) - nn)
        d = self.node_dofs[:, active].T                                  # (n_active, 3)
        rows = np.broadcast_to(d[:, :, None], h.shape).ravel()
        cols = np.broadcast_to(d[:, None, :], h.shape).ravel()
        self.last_tangent = (k, rows, cols, h.ravel())      # its parts, for ContactSolver
        return (k + sp.coo_matrix((h.ravel(), (rows, cols)), shape=k.shape)).tocsr()

    def min_volume_ratio(self, u):
        return self.body.min_volume_ratio(u)

    def largest_gap(self, u):
        """The largest |g| of a node the sphere pushes, m (0 for the exact constraint)."""
        g = self.contact(u)[4]
        return float(np.abs(g).max()) if len(g) else 0.0

    def update_multipliers(self, u):
        """The augmented Lagrangian's update lambda <- max(0, lambda + k g)."""
        v = self._offset + u[self.node_dofs].T
        g = self.radius - np.linalg.norm(v, axis=1)
        self.multiplier = np.maximum(0.0, self.multiplier + self.stiffness * g)

    def reaction(self, u):
        """The sphere's reaction on the quarter model (N, positive up: minus the sum of the y
        components of its forces on the body), the largest distance from the y axis of a node
        it pushes (m, deformed positions) and the number of those nodes."""
        active, p, n, _, _ = self.contact(u)
        if len(active) == 0:
            return 0.0, 0.0, 0
        x = self.rest[active] + u[self.node_dofs[:, active]].T
        return float(p @ -n[:, 1]), float(np.hypot(x[:, 0], x[:, 2]).max()), len(active)


def nested_dissection(points, planes, leaf=64):
    """A fill-reducing elimination order of the dofs located at `points` (3, n) of a box mesh
    whose cells' faces lie on the coordinate planes `planes` (one sorted array per axis):
    recursively, the dofs on the middle cell-face plane across the side with the most such
    planes inside (a separator: no element crosses a cell face) go after the dofs on either
    side of it. Used with SuperLU's natural order (OrderedLU): on the 44k-dof cube it factors
    ~4x faster than MMD with a third to a half of the fill."""
    order = []

    def split(idx):
        if len(idx) <= leaf:
            order.append(idx)
            return
        p = points[:, idx]
        inner = [pl[(pl > p[a].min() + 1e-12) & (pl < p[a].max() - 1e-12)]
                 for a, pl in enumerate(planes)]
        axis = int(np.argmax([len(c) for c in inner]))
        if len(inner[axis]) == 0:
            order.append(idx)
            return
        cut = inner[axis][len(inner[axis]) // 2]
        on = np.abs(p[axis] - cut) <= 1e-12
        split(idx[(p[axis] < cut) & ~on])
        split(idx[(p[axis] > cut) & ~on])
        order.append(idx[on])

    split(np.arange(points.shape[1]))
    perm = np.concatenate(order)
    assert np.array_equal(np.sort(perm), np.arange(points.shape[1]))
    return perm


class ContactSolver:
    """Solves newton()'s systems K_ff du = r for a SphereContact: K = its body's tangent B plus
    the contact Hessian C (3x3 blocks on the nodes the sphere pushes). One LU, of the K_ff of
    an earlier system (A = B0 + C0), serves many: C - C0 is low-rank (the contact nodes' dofs),
    and the Woodbury identity corrects A for it, (A + E H E^T)^-1 r = y - Z (I + H E^T Z)^-1
    H E^T y, y = A^-1 r, Z = A^-1 E, H = (C - C0) on the dofs E picks (Z's columns cached per
    dof while the LU is kept). While B is still B0 (always, for linear elasticity; for snh while
    SphereContact reuses it) and at most CONTACT_COLUMNS new columns are needed, that is a
    direct solve with every changed dof. Otherwise it preconditions GMRES on K with only the
    large changes (a node come into or out of contact, or a block changed by more than
    CONTACT_CHANGE of the penalty stiffness) in E, the rest (B - B0, the normals' slow turning)
    left to GMRES; when 12 iterations do not bring the true residual to GMRES_FORCING, K_ff is
    factorised anew. So the contact's active set can change without a factorisation.
    `perm`: the LU's elimination order of the free dofs."""

    def __init__(self, contact, free, perm):
        self.contact, self.free, self.perm = contact, free, perm
        self.position = np.full(contact.ndofs, -1)
        self.position[free] = np.arange(len(free))        # global dof -> free index
        self.lu, self.columns, self.body, self.reference = None, {}, None, None
        self.factorisations = 0

    def _contact_hessian(self):
        """The last tangent's contact Hessian on the free dofs (CSR)."""
        _, rows, cols, vals = self.contact.last_tangent
        fr, fc = self.position[rows], self.position[cols]
        keep = (fr >= 0) & (fc >= 0)
        n = len(self.free)
        return sp.coo_matrix((vals[keep], (fr[keep], fc[keep])), shape=(n, n)).tocsr()

    def _factorise(self, k, body, hessian):
        self.lu, self.columns = None, {}                  # free the old one first (peak memory)
        self.lu = OrderedLU(k, self.perm)
        self.body, self.reference = body, hessian
        self.factorisations += 1

    def _column(self, j):
        """A^-1 e_j (cached)."""
        if j not in self.columns:
            e = np.zeros(len(self.free))
            e[j] = 1.0
            self.columns[j] = self.lu.solve(e)
        return self.columns[j]

    def _woodbury(self, change, dofs):
        """x -> (A + E H E^T)^-1 x, H = `change` on `dofs` (free indices)."""
        if len(dofs) == 0:
            return self.lu.solve
        h = change[dofs][:, dofs].toarray()
        z = np.column_stack([self._column(j) for j in dofs])
        small = np.linalg.inv(np.eye(len(dofs)) + h @ z[dofs])

        def apply(x):
            y = self.lu.solve(x)
            return y - z @ (small @ (h @ y[dofs]))
        return apply

    def solve(self, k, r):
        body, hessian = self.contact.last_tangent[0], self._contact_hessian()
        if self.lu is None:
            self._factorise(k, body, hessian)
            return self.lu.solve(r)
        change = (hessian - self.reference).tocsr()
        change.eliminate_zeros()
        row_max = (abs(change).max(axis=1).toarray().ravel() if change.nnz
                   else np.zeros(change.shape[0]))
        changed = np.nonzero(row_max > 0.0)[0]
        if body is self.body and sum(j not in self.columns for j in changed) <= CONTACT_COLUMNS:
            return self._woodbury(change, changed)(r)
        large = np.nonzero(row_max > CONTACT_CHANGE * self.contact.stiffness)[0]
        prec = sla.LinearOperator(k.shape, self._woodbury(change, large))
        x, _ = sla.gmres(k, r, M=prec, rtol=CONTACT_GMRES_RTOL, atol=0.0, restart=12,
                         maxiter=1)
        if np.linalg.norm(k @ x - r) <= GMRES_FORCING * np.linalg.norm(r):
            return x
        self._factorise(k, body, hessian)
        return self.lu.solve(r)


class OrderedLU:
    """Sparse LU of the symmetric matrix `k` in the elimination order `perm` (SuperLU, natural
    order on the permuted matrix); .solve(r) solves k x = r."""

    def __init__(self, k, perm):
        self.perm, self.inverse = perm, np.argsort(perm)
        self.lu = sla.splu(k[perm][:, perm].tocsc(), permc_spec="NATURAL",
                           options=dict(SymmetricMode=True))

    def solve(self, r):
        return self.lu.solve(r[self.perm])[self.inverse]


def box_tets_ours(size, cells):
    """Our side's box lattice (softbody/src/methods/statics.rs, box_tets, transcribed): nodes
    (n, 3) m and tets (m, 4) of `size` split into `cells` cells of six tets each, around each
    cell's main diagonal (cell corner q = bits x, y, z of q)."""
    nx, ny, nz = cells
    step = np.asarray(size, dtype=float) / np.asarray(cells)
    # node i (ny + 1)(nz + 1) + j (nz + 1) + k at (i, j, k) * step
    x = np.stack(np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), np.arange(nz + 1),
                             indexing="ij"), axis=-1).reshape(-1, 3) * step
    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz),
                                               indexing="ij"))
    corners = np.stack([(i + (q & 1)) * (ny + 1) * (nz + 1) + (j + ((q >> 1) & 1)) * (nz + 1)
                        + (k + ((q >> 2) & 1)) for q in range(8)], axis=1)
    split = np.array([[0, 1, 3, 7], [0, 1, 7, 5], [0, 5, 7, 4], [0, 3, 2, 7], [0, 2, 6, 7],
                      [0, 6, 4, 7]])
    return x, corners[:, split].reshape(-1, 4)


def box_is_ours(size, cells):
    """Whether box() (scikit-fem's MeshTet.init_tensor) has the same nodes and the same tets,
    as sets of vertex positions, as our side's lattice (box_tets_ours): then P1 on it is our
    discretisation node for node (the node numbering differs)."""
    x, tets = box_tets_ours(size, cells)
    mesh = box(*size, *cells)
    key = lambda p: tuple(np.round(np.asarray(p) / 1e-9).astype(np.int64))
    ours = {frozenset(key(x[q]) for q in t) for t in tets}
    theirs = {frozenset(key(mesh.p[:, q]) for q in t) for t in mesh.t.T}
    same_nodes = (len(x) == mesh.p.shape[1]
                  and {key(p) for p in x} == {key(p) for p in mesh.p.T})
    return same_nodes and len(ours) == len(tets) == mesh.t.shape[1] and ours == theirs


def hertz_force(depth_m):
    """Hertz's force, N, of a rigid sphere (a paraboloid) of radius INDENTER_R pressed depth_m
    into a half-space of Young's modulus SLAB_E and Poisson's ratio NU."""
    return 4.0 / 3.0 * SLAB_E / (1.0 - NU ** 2) * math.sqrt(INDENTER_R) * depth_m ** 1.5


def sneddon_sphere_force(depth_m):
    """Force, N, of a rigid *sphere* (not a paraboloid) of radius INDENTER_R pressed depth_m
    into a linear-elastic half-space (Sneddon 1965): d = a/2 ln((R + a)/(R - a)),
    F = E*/2 ((a^2 + R^2) ln((R + a)/(R - a)) - 2 a R), E* = E/(1 - nu^2); a by bisection."""
    big_r = INDENTER_R
    lo, hi = 0.0, big_r * (1.0 - 1e-12)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if 0.5 * mid * math.log((big_r + mid) / (big_r - mid)) < depth_m:
            lo = mid
        else:
            hi = mid
    a = 0.5 * (lo + hi)
    log = math.log((big_r + a) / (big_r - a))
    return 0.5 * SLAB_E / (1.0 - NU ** 2) * ((a * a + big_r * big_r) * log - 2.0 * a * big_r)


def layer_factor(depth_m):
    """Dimitriadis et al. 2002 (eq. 13, to chi^3): the force of a paraboloid on an elastic
    layer SLAB thick bonded to a rigid base over Hertz's, chi = sqrt(R d) / SLAB (a laterally
    infinite layer, small chi)."""
    chi = math.sqrt(INDENTER_R * depth_m) / SLAB
    alpha0 = -(1.2876 - 1.4678 * NU + 1.3442 * NU ** 2) / (1.0 - NU)
    beta0 = (0.6387 - 1.0277 * NU + 1.5164 * NU ** 2) / (1.0 - NU)
    return (1.0 - 2.0 * alpha0 / math.pi * chi + 4.0 * alpha0 ** 2 / math.pi ** 2 * chi ** 2
            - 8.0 / math.pi ** 3 * (alpha0 ** 3 + 4.0 * math.pi ** 2 / 15.0 * beta0) * chi ** 3)


def indent_problem(k, order):
    """The indentation's discretisation at k cells per SLAB edge (P1 with one quadrature point,
    exact): (disc, dirichlet dofs (all held at 0), the base's y dofs)."""
    disc = Discretisation(box(SLAB, SLAB, SLAB, k, k, k), order,
                          intorder=1 if order == 1 else None)
    dofs = disc.vb.get_dofs
    base = dofs(lambda x: np.isclose(x[1], 0.0))
    sym_x = dofs(lambda x: np.isclose(x[0], 0.0)).all("u^1")
    sym_z = dofs(lambda x: np.isclose(x[2], 0.0)).all("u^3")
    dirichlet = np.unique(np.concatenate([base.all(), sym_x, sym_z]))
    return disc, dirichlet, base.all("u^2")


def indent_path(contact, mat, free, depths_m, solver):
    """Moves the sphere of `contact` down through depths_m (m, increasing) from rest: to each
    depth in one load step from the last (halved while Newton fails; the predictor extrapolates
    the last two states), then multiplier updates until every contact node's |g| <=
    CONTACT_TOL d. Yields (depth, u, dict(newton iterations, steps, updates, wall_s)) per depth;
    raises NotConverged."""
    zero = np.zeros(contact.ndofs)
    hist = [(0.0, zero)]
    for depth in depths_m:
        t_start, iters, steps = time.time(), 0, 0
        dt = depth - hist[-1][0]
        while hist[-1][0] < depth:
            t0, u0 = hist[-1]
            t1 = depth if t0 + dt >= depth * (1.0 - 1e-9) else t0 + dt
            if len(hist) >= 2:
                tp, up = hist[-2]
                pred = u0 + (t1 - t0) / (t0 - tp) * (u0 - up)
            else:
                pred = u0.copy()
            contact.set_centre([0.0, SLAB + INDENTER_R - t1, 0.0])
            try:
                u1, n = newton(contact, mat, pred, free, zero, solver, [], line_min=True)
            except NotConverged:
                dt /= 2
                if dt < 1e-3 * depth:
                    raise
                continue
            iters, steps = iters + n, steps + 1
            hist = [hist[-1], (t1, u1)]
        u, updates = hist[-1][1], 0
        while contact.largest_gap(u) > CONTACT_TOL * depth:
            if updates == CONTACT_UPDATES:
                raise NotConverged(f"contact gap {contact.largest_gap(u) / depth:.1e} d after "
                                   f"{updates} multiplier updates")
            contact.update_multipliers(u)
            u, n = newton(contact, mat, u, free, zero, solver, [], line_min=True)
            iters, updates = iters + n, updates + 1
        hist[-1] = (depth, u)
        yield depth, u, dict(newton=iters, steps=steps, updates=updates,
                             wall_s=time.time() - t_start)


def indent(k, order, law, depths_mm=INDENT_DEPTHS_MM):
    """The slab ([0, SLAB]^3, k^3 cells, P`order`, law "snh" or "linear") indented by the sphere
    through each of depths_mm, in order. One row per depth: value = force_n = the whole
    sphere's reaction (4 x the quarter's), N; contact_radius_mm = the largest distance from the
    axis of a node in contact, mm (deformed); the Newton iterations, load steps, multiplier
    updates and seconds from the previous depth (the first also counts the setup); gap_rel =
    the largest |g| of a contact node / d; base_rel = |base reaction / sphere reaction - 1|
    (the equilibrium's check); Hertz's force and contact radius, Sneddon's sphere and the
    layer factor (module comment above)."""
    t_start = time.time()
    disc, dirichlet, base_y = indent_problem(k, order)
    if law == "snh":
        body, mat = disc, snh_parameters(SLAB_E)
    else:
        body, mat = LinearBody(disc, SLAB_E), None
    contact = SphereContact(body, INDENTER_R, CONTACT_STIFFNESS)
    free = np.setdiff1d(np.arange(disc.ndofs), dirichlet)
    planes = [np.linspace(0.0, SLAB, k + 1)] * 3
    perm = nested_dissection(disc.vb.doflocs[:, free], planes)
    solver = ContactSolver(contact, free, perm)
    setup_s = time.time() - t_start
    rows, failure = {}, ""
    try:
        for depth, u, facts in indent_path(contact, mat, free, [d * 1e-3 for d in depths_mm],
                                           solver):
            force, radius, n_active = contact.reaction(u)
            base = float(body.forces(u, mat)[0][base_y].sum())
            rows[depth] = dict(value=4.0 * force, contact_radius_mm=1e3 * radius,
                               active_nodes=n_active, gap_rel=contact.largest_gap(u) / depth,
                               base_rel=abs(base / force - 1.0),
                               min_det_f=disc.min_volume_ratio(u) if law == "snh" else "",
                               **facts)
    except NotConverged as e:
        failure = f"did not converge: {e}"
    peak = peak_rss_mb()
    for i, d in enumerate(depths_mm):
        depth = d * 1e-3
        row = dict(problem="indent", quantity="force_n", case=f"d={d:g}mm", law=law,
                   element=f"P{order}", level=k, dofs=disc.ndofs, d_mm=d,
                   hertz_n=hertz_force(depth), hertz_radius_mm=1e3 * math.sqrt(INDENTER_R * depth),
                   sphere_n=sneddon_sphere_force(depth), layer_factor=layer_factor(depth),
                   peak_mb=peak or "", factorisations=solver.factorisations, note=failure)
        if depth in rows:
            row.update(rows[depth])
            if i == 0:
                row["wall_s"] += setup_s
        else:
            row["value"] = float("nan")
        yield row


INDENT_COLS = ["problem", "law", "element", "k", "d_mm", "force_n", "hertz_n", "fem_over_hertz",
               "force_change_pct", "contact_radius_mm", "hertz_radius_mm", "active_nodes",
               "newton", "steps", "updates", "wall_s", "dofs", "gap_rel", "base_rel",
               "min_det_f", "sphere_n", "layer_factor", "factorisations", "peak_mb", "note"]


def indent_csv_row(r):
    """A row of indent.csv (INDENT_COLS) from an indent() row; a failed level's force is empty."""
    ok = math.isfinite(r["value"])
    out = dict(r, k=r["level"], force_n=r["value"] if ok else "",
               fem_over_hertz=r["value"] / r["hertz_n"] if ok else "",
               force_change_pct=r.get("change_pct", ""), d_mm=f"{r['d_mm']:g}")
    return [fmt(out.get(c, ""), 10 if c in ("force_n", "hertz_n", "sphere_n") else 6)
            for c in INDENT_COLS]


def indent_line(r):
    """The RESULT line of an indent() row: the key set of results.txt's FEM side (level = the
    FEM level k, fem = its force N, fem_change_pct = its change from the previous level of the
    same element and law, %), then what identifies and explains it."""
    def num(x, digits):
        return "nan" if x == "" or not math.isfinite(x) else f"{x:.{digits}f}"
    return (f"RESULT reference.fem problem=indent quantity=force_n case={r['case']} "
            f"level={r['level']} fem={num(r['value'], 6)} "
            f"fem_change_pct={num(r.get('change_pct', ''), 2)} fem_level={r['level']} "
            f"element={r['element']} law={r['law']} hertz={r['hertz_n']:.6f} "
            f"fem_over_hertz={num(r['value'] / r['hertz_n'], 4)} "
            f"contact_radius_mm={num(r.get('contact_radius_mm', ''), 3)} dofs={r['dofs']}")


def merge_indent_answers(rows):
    """Puts the indentation's answers into answers.json (written by --all, which keeps them):
    per law and depth the finest P2 level, as for the other problems, with Hertz's force."""
    path = OUT_DIR / "answers.json"
    answers = json.loads(path.read_text()) if path.exists() else {"meta": {}}
    out = {}
    for r in rows:
        if r["element"] != "P2":
            continue
        change = r.get("change_pct", "")
        if not math.isfinite(r["value"]):
            continue
        out[f"d={r['d_mm']:g}mm {r['law']}"] = {
            "value": float(r["value"]), "level": int(r["level"]), "dofs": int(r["dofs"]),
            "change_pct": float(change) if change != "" else None,
            "converged": bool(change != "" and abs(change) <= CONVERGED_PCT),
            "hertz": float(r["hertz_n"]), "fem_over_hertz": float(r["value"] / r["hertz_n"])}
    answers["indent"] = {"force_n": out}
    answers["meta"]["indent_generated_by"] = "scripts/fem-reference --indent"
    with open(path, "w") as fh:
        json.dump(answers, fh, indent=2)
        fh.write("\n")


def run_indent():
    """--indent: every law at every level of INDENT_LEVELS; writes indent.csv and indent.txt,
    merges the finest P2 answers into answers.json, prints the comparison with Hertz."""
    t_all = time.time()
    for k in sorted({k for _, k in INDENT_LEVELS}):
        assert box_is_ours((SLAB,) * 3, (k, k, k)), f"box() is not our lattice at k = {k}"
    print(f"# box() = our lattice (same nodes and tets) at k = "
          f"{sorted({k for _, k in INDENT_LEVELS})}", flush=True)
    rows, last, peaks = [], {}, []
    for law in INDENT_LAWS:
        for order, k in INDENT_LEVELS:
            peak_rss_mb(reset=True)
            t = time.time()
            for r in indent(k, order, law):
                key = (law, r["element"], r["d_mm"])
                prev = last.get(key)
                ok = prev is not None and math.isfinite(prev) and math.isfinite(r["value"])
                r["change_pct"] = 100.0 * (r["value"] / prev - 1.0) if ok else ""
                last[key] = r["value"]
                rows.append(r)
                print(indent_line(r), flush=True)
            peaks.append(r["peak_mb"] or 0.0)
            print(f"#   {law} P{order} k={k}: {r['dofs']} dofs, {time.time() - t:.1f} s, "
                  f"{r['factorisations']} LU, peak {fmt(r['peak_mb'], 4)} MB{', ' + r['note'] if r['note'] else ''}",
                  flush=True)
    OUT_DIR.mkdir(parents=True, exist_ok=True)
    with open(OUT_DIR / "indent.csv", "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(INDENT_COLS)
        for r in rows:
            w.writerow(indent_csv_row(r))
    (OUT_DIR / "indent.txt").write_text("".join(indent_line(r) + "\n" for r in rows))
    merge_indent_answers(rows)
    # FEM against Hertz: the finest level of each element and law per depth, and the closed-form
    # estimate of a rigid sphere on a bonded layer (Sneddon's sphere x the layer factor)
    finest = {}
    for r in rows:
        finest[(r["law"], r["element"], r["d_mm"])] = r
    print("# d_mm  a_mm  hertz_N  sphere/hertz  layer  estimate/hertz | FEM/hertz: "
          + "  ".join(f"{law} {el} k={finest[(law, el, INDENT_DEPTHS_MM[0])]['level']}"
                      for law in INDENT_LAWS for el in ("P1", "P2")))
    for d in INDENT_DEPTHS_MM:
        r0 = finest[(INDENT_LAWS[0], "P2", d)]
        sphere = r0["sphere_n"] / r0["hertz_n"]
        print(f"# {d:5g} {r0['hertz_radius_mm']:5.2f} {r0['hertz_n']:8.5f} {sphere:8.4f} "
              f"{r0['layer_factor']:8.4f} {sphere * r0['layer_factor']:8.4f}        | "
              + "  ".join(f"{finest[(law, el, d)]['value'] / r0['hertz_n']:8.4f}"
                          for law in INDENT_LAWS for el in ("P1", "P2")))
    worst_gap = max((r["gap_rel"] for r in rows if "gap_rel" in r), default=float("nan"))
    worst_base = max((r["base_rel"] for r in rows if "base_rel" in r), default=float("nan"))
    print(f"# contact: largest |gap| of a contact node {worst_gap:.1e} d; base reaction vs sphere "
          f"reaction {worst_base:.1e}; peak {max(peaks):.0f} MB")
    print(f"wrote {OUT_DIR.relative_to(ROOT)}/indent.csv, indent.txt (and the indentation into "
          f"answers.json) in {time.time() - t_all:.0f} s")
    return 0 if all(math.isfinite(r["value"]) for r in rows) else 1


# --------------------------------------------------------------------------------------
# Bunny (--bunny): our fictitious-domain lattice under its own weight
# --------------------------------------------------------------------------------------
# Our side exports the bunny it solves (JSON, see run_bunny): a tet lattice covering the
# bunny, each tet with a weight w in (0, 1] = the fraction of it inside the bunny's surface,
# which scales both its stiffness (mu w, lam w: E w with the same nu) and its mass (rho w), the
# base (nodes with y <= min y + 8 % of the height) fixed, and our static displacement of every
# node under full gravity. Here the same discrete problem is solved by Newton on the same mesh
# with P1 (our discretisation) and with finer spaces that keep the weights as they are: P1 on
# the mesh refined once (each child tet inherits its parent's weight), P2 on the mesh and P2
# on the refined mesh -- so what changes between these levels is the FEM's resolution of the
# given weighted lattice, not the geometry.

BUNNY_LEVELS = ("P1", "P1_refined", "P2", "P2_refined")  # in order of accuracy
BUNNY_MAX_DOFS = 150_000   # a level with more dofs is skipped (P2_refined of the 5 % lattice:
                           # 404k dofs, beyond a sparse LU in a few GB)
MATERIAL_WEIGHT = 0.5      # material node: a node of at least one tet with w >= this
INTERIOR_WEIGHT = 0.99     # interior node: every tet of the node has w >= this


def refined_with_parents(mesh):
    """scikit-fem's uniform refinement of `mesh` (every tet into eight) and the parent of
    every child tet: the parent tet that contains the child's centroid (scikit-fem orders the
    children in blocks that depend on its choice of inner diagonal, so the order is not relied
    on). A child's centroid has barycentric coordinates >= 1/8 in its parent (1/8 is the least,
    on both the corner and the inner children), so it lies in no other tet; candidates are the
    tets with the nearest centroids. Checked: every parent has eight children and their volumes
    add up to the parent's."""
    fine = mesh.refined()
    n_parents = mesh.t.shape[1]
    cent = fine.p[:, fine.t].mean(axis=1).T                  # (n_children, 3)
    v = np.moveaxis(mesh.p[:, mesh.t], 0, -1)                # (4, n_parents, 3)
    to_bary = np.linalg.inv(np.stack([v[1] - v[0], v[2] - v[0], v[3] - v[0]], axis=-1))
    tree = scipy.spatial.cKDTree(v.mean(axis=0))
    parent = np.full(len(cent), -1)
    for k in (8, 32, 128, 512):
        todo = np.nonzero(parent < 0)[0]
        if len(todo) == 0:
            break
        cand = tree.query(cent[todo], k=min(k, n_parents))[1].reshape(len(todo), -1)
        lam = np.einsum("nkij,nkj->nki", to_bary[cand], cent[todo, None, :] - v[0][cand])
        worst = np.minimum(lam.min(axis=2), 1.0 - lam.sum(axis=2))       # (n, k)
        best = worst.argmax(axis=1)
        found = worst[np.arange(len(todo)), best] >= 0.125 - 1e-9
        parent[todo[found]] = cand[found, best[found]]
    assert parent.min() >= 0, "a child tet's centroid lies in no parent (with >= 1/8 margins)"
    assert np.array_equal(np.bincount(parent, minlength=n_parents), np.full(n_parents, 8))

    def volumes(m):
        q = m.p[:, m.t]
        return np.abs(np.einsum("ie,ie->e", np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0],
                                                      axis=0), q[:, 3] - q[:, 0])) / 6.0
    child_sum = np.bincount(parent, volumes(fine), minlength=n_parents)
    assert np.allclose(child_sum, volumes(mesh), rtol=1e-9, atol=0.0)
    return fine, parent


def bunny_solid(data):
    """The tets the FEM keeps, and the nodes it solves for (boolean masks). A lattice of tets
    cut by a surface can leave a tet (or a group) hanging from the rest by one edge or one
    vertex: a hinge, a mechanism whose static answer is a rigid swing under gravity (a
    pendulum hanging down), not elasticity, and which makes the stiffness singular. Kept: the
    groups of face-connected tets anchored by >= 3 non-collinear fixed nodes, then, repeatedly,
    every group whose vertices shared with the kept ones or fixed span a plane (>= 3
    non-collinear). The rest are left out of the FEM, and their nodes not on a kept tet out of
    every statistic (ours included)."""
    tets = np.asarray(data["tets"])
    nodes = np.asarray(data["nodes"], dtype=float)
    n_tets, n_nodes = len(tets), len(nodes)
    faces = np.sort(tets[:, [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]]], axis=2).reshape(-1, 3)
    _, face_id = np.unique(faces, axis=0, return_inverse=True)
    owner = np.repeat(np.arange(n_tets), 4)
    order = np.argsort(face_id.ravel(), kind="stable")
    fid, own = face_id.ravel()[order], owner[order]
    shared = fid[1:] == fid[:-1]                       # a face met twice: two tets share it
    adj = sp.coo_matrix((np.ones(int(shared.sum())), (own[1:][shared], own[:-1][shared])),
                        shape=(n_tets, n_tets))
    n_groups, group = scipy.sparse.csgraph.connected_components(adj, directed=False)
    pinned = np.zeros(n_nodes, bool)
    pinned[np.asarray(data["fixed"])] = True
    kept = np.zeros(n_groups, bool)

    def spans_plane(vertices):
        if len(vertices) < 3:
            return False
        x = nodes[vertices]
        return np.linalg.matrix_rank(x[1:] - x[0], tol=1e-6 * np.ptp(nodes, axis=0).max()) >= 2

    group_nodes = [np.unique(tets[group == c]) for c in range(n_groups)]
    changed = True
    while changed:
        changed = False
        for c in np.nonzero(~kept)[0]:
            if spans_plane(group_nodes[c][pinned[group_nodes[c]]]):
                kept[c] = changed = True
                pinned[group_nodes[c]] = True
    kept_tets = kept[group]
    solved = np.zeros(n_nodes, bool)
    solved[tets[kept_tets].ravel()] = True
    return kept_tets, solved


def bunny_level(data, element, kept_tets):
    """One FEM level of an exported bunny (only the tets `kept_tets`, see bunny_solid): the
    static displacement (m) at the mesh's own nodes that those tets use (vertex dofs), shape
    (n_solved_nodes, 3), in node order, and a dict of solver facts; None if the level has more
    than BUNNY_MAX_DOFS dofs."""
    all_nodes = np.asarray(data["nodes"], dtype=float)
    tets = np.asarray(data["tets"])[kept_tets]
    used, local = np.unique(tets, return_inverse=True)
    nodes = all_nodes[used]
    weight = np.asarray(data["weight"], dtype=float)[kept_tets]
    mesh = MeshTet(nodes.T.copy(), local.reshape(tets.shape).T.copy())
    assert np.array_equal(mesh.p, nodes.T), "MeshTet moved the nodes"
    if element.endswith("_refined"):
        order = 1 if element.startswith("P1") else 2
        mesh, parent = refined_with_parents(mesh)
        weight = weight[parent]
    else:
        order = 1 if element == "P1" else 2
    # the original nodes among the (refined) mesh's vertices, by position
    near = scipy.spatial.cKDTree(mesh.p.T).query(nodes)
    assert near[0].max() < 1e-12, "an original node is not a vertex of the refined mesh"
    n_vertices, n_edges = mesh.p.shape[1], mesh.edges.shape[1]
    ndofs = 3 * (n_vertices + (n_edges if order == 2 else 0))
    facts = dict(element=element, tets=mesh.t.shape[1], dofs=ndofs)
    if ndofs > BUNNY_MAX_DOFS:
        return None, dict(facts, note=f"skipped: {ndofs} dofs > {BUNNY_MAX_DOFS}")
    t = time.time()
    disc = Discretisation(mesh, order)
    assert disc.ndofs == ndofs
    # material: stiffness and density scaled per tet by its weight (E w, same nu: mu w, lam' w,
    # gamma unchanged); mu and lam' broadcast over the quadrature points
    if abs(float(data["nu"]) - NU) > 1e-12:
        raise ValueError(f"nu = {data['nu']}, this script's material has nu = {NU}")
    mu, lam_p, gamma = snh_parameters(float(data["young_pa"]))
    w = weight[:, None]
    mat = (mu * w, lam_p * w, gamma)
    rho, g = float(data["density_kg_m3"]), np.asarray(data["gravity"], dtype=float)
    wq = np.broadcast_to(w, disc.dx.shape)
    fg = asm(LinearForm(lambda v, p: rho * p["wt"] * (g[0] * v[0] + g[1] * v[1] + g[2] * v[2])),
             disc.vb, wt=wq)
    mass = rho * float(np.sum(wq * disc.dx))
    assert abs(np.linalg.norm(fg.reshape(-1, 3).sum(axis=0)) / (mass * np.linalg.norm(g)) - 1) < 1e-9
    # fixed: every dof located in the base, y <= cut (vertex, and for P2 midside, dofs)
    fixed_nodes = np.asarray(data["fixed"])
    cut = all_nodes[fixed_nodes, 1].max() + 1e-9
    assert set(np.nonzero(all_nodes[:, 1] <= cut)[0]) == set(fixed_nodes.tolist())
    fixed = np.nonzero(disc.vb.doflocs[1] <= cut)[0]
    # linear-elastic predictor (the tangent at rest), whose LU also seeds the Newton solves
    k0 = disc.tangent(np.zeros(disc.ndofs), mat)
    u_lin, lu_lin = solve_linear(disc, k0, fixed, 0.0, fg)
    del k0
    if not np.abs(u_lin).max() < np.ptp(all_nodes, axis=0).max():
        raise RuntimeError(f"{element}: linear answer of {np.abs(u_lin).max():.3g} m: singular "
                           "stiffness (a mechanism that bunny_solid did not remove?)")
    seed = [lu_lin]           # handed over without a reference left here (peak memory)
    del lu_lin
    sol, steps, iters, facts_lu = load_path(disc, mat, fixed, 0.0, fg, [1.0], 1.0, u_lin,
                                            lu=seed.pop())
    u = sol[1.0]
    fint = disc.forces(u, mat)[0]
    free = np.setdiff1d(np.arange(disc.ndofs), fixed)
    residual = np.linalg.norm((fg - fint)[free]) / np.linalg.norm(fg)
    vdofs = disc.vb.nodal_dofs[:, near[1]]                  # (3, n_nodes)
    return u[vdofs].T.copy(), dict(
        facts, fixed_dofs=len(fixed), mass_kg=mass, min_det_f=disc.min_volume_ratio(u),
        residual=residual, time_s=time.time() - t, linear_max_mm=1e3 * np.linalg.norm(
            u_lin[vdofs].T, axis=1).max(),
        note=f"{steps} steps, {iters} Newton its, {facts_lu} LU")


def bunny_node_sets(data):
    """(material, interior) boolean masks over the nodes: material = a node of at least one
    tet with w >= MATERIAL_WEIGHT (the rest, fringe nodes, touch only tets mostly outside the
    surface: fictitious material); interior = all of the node's tets have w >= INTERIOR_WEIGHT."""
    tets = np.asarray(data["tets"])
    w = np.repeat(np.asarray(data["weight"], dtype=float), 4)
    n = len(data["nodes"])
    wmax, wmin = np.zeros(n), np.full(n, np.inf)
    np.maximum.at(wmax, tets.ravel(), w)
    np.minimum.at(wmin, tets.ravel(), w)
    return wmax >= MATERIAL_WEIGHT, wmin >= INTERIOR_WEIGHT


def peak_rss_mb(reset=False):
    """Peak resident memory of this process (VmHWM, MB); reset=True restarts the peak (Linux
    /proc/self/clear_refs), so that it covers one level. None where /proc lacks it."""
    try:
        if reset:
            Path("/proc/self/clear_refs").write_text("5")
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return None


BUNNY_COLS = ["file", "cell_frac", "level", "element", "nodes", "left_out_tets",
              "left_out_nodes", "tets", "dofs", "material_nodes", "interior_nodes", "fem_max_mm", "fem_mean_mm",
              "fem_change_pct", "fem_mean_change_pct", "ours_max_mm", "ours_mean_mm",
              "field_rms_pct", "material_field_rms_pct", "interior_field_rms_pct",
              "field_max_err_pct", "ours_file_max_mm", "ours_steps", "ours_budget", "newton", "residual",
              "min_det_f", "time_s", "peak_mb"]


def bunny_line(r):
    keys = ["level", "element", "fem_max_mm", "fem_mean_mm", "fem_change_pct", "ours_max_mm",
            "ours_mean_mm", "field_rms_pct", "material_field_rms_pct", "fem_mean_change_pct",
            "interior_field_rms_pct", "field_max_err_pct", "dofs", "left_out_nodes"]
    return "RESULT reference.fem problem=bunny quantity=field_rms_pct " + " ".join(
        f"{k}={fmt(r[k], 5) if r[k] != '' else 'nan'}" for k in keys)


def run_bunny(files):
    """--bunny FILE...: for each exported bunny, the FEM levels of BUNNY_LEVELS that fit, and
    our displacement field against each (module comment above; the fields in the docstring)."""
    t_all = time.time()
    rows = []
    for path in files:
        data = json.loads(Path(path).read_text())
        kept_tets, solved = bunny_solid(data)
        ours_all = np.asarray(data["ours"], dtype=float)
        left_out = np.nonzero(~kept_tets)[0]
        if len(left_out):
            free_nodes = np.nonzero(~solved)[0]
            print(f"# {Path(path).name}: left out {len(left_out)} hinged tet(s) {left_out.tolist()} "
                  f"(weights {np.asarray(data['weight'])[left_out].tolist()}) and their "
                  f"{len(free_nodes)} free node(s) {free_nodes.tolist()}, where ours moved "
                  f"{(1e3 * np.linalg.norm(ours_all[free_nodes], axis=1)).round(2).tolist()} mm",
                  flush=True)
        ours = ours_all[solved]
        n_nodes = len(ours)
        material, interior = (m[solved] for m in bunny_node_sets(data))
        ours_norm = np.linalg.norm(ours, axis=1)
        prev = None
        for element in BUNNY_LEVELS:
            peak_rss_mb(reset=True)
            u, facts = bunny_level(data, element, kept_tets)
            if u is None:
                print(f"# {Path(path).name} {element}: {facts['note']}", flush=True)
                continue
            norm = np.linalg.norm(u, axis=1)
            fem_max, fem_mean = 1e3 * norm.max(), 1e3 * norm.mean()
            err2 = np.sum((ours - u) ** 2, axis=1)

            def rms_pct(mask):
                return 100.0 * math.sqrt(err2[mask].mean()) / norm.max()

            r = dict(file=Path(path).name, cell_frac=float(data["cell_frac"]),
                     level=f"c{float(data['cell_frac']):.3f}", element=element, nodes=n_nodes,
                     left_out_tets=len(left_out), left_out_nodes=int((~solved).sum()),
                     ours_file_max_mm=1e3 * np.linalg.norm(ours_all, axis=1).max(),
                     tets=facts["tets"], dofs=facts["dofs"], material_nodes=int(material.sum()),
                     interior_nodes=int(interior.sum()), fem_max_mm=fem_max, fem_mean_mm=fem_mean,
                     fem_change_pct=100.0 * (fem_max / prev[0] - 1) if prev else "",
                     fem_mean_change_pct=100.0 * (fem_mean / prev[1] - 1) if prev else "",
                     ours_max_mm=1e3 * ours_norm.max(), ours_mean_mm=1e3 * ours_norm.mean(),
                     field_rms_pct=rms_pct(np.ones(n_nodes, bool)),
                     material_field_rms_pct=rms_pct(material),
                     interior_field_rms_pct=rms_pct(interior),
                     field_max_err_pct=100.0 * math.sqrt(err2.max()) / norm.max(),
                     ours_steps=data.get("ours_steps", ""), ours_budget=data.get("ours_budget", ""),
                     newton=facts["note"], residual=facts["residual"],
                     min_det_f=facts["min_det_f"], time_s=facts["time_s"],
                     peak_mb=peak_rss_mb() or "")
            prev = (fem_max, fem_mean)
            rows.append(r)
            print(bunny_line(r), flush=True)
            print(f"#   {facts['dofs']} dofs, {facts['tets']} tets, {facts['fixed_dofs']} fixed "
                  f"dofs, mass {facts['mass_kg']:.4f} kg, linear max {facts['linear_max_mm']:.3f} "
                  f"mm, {facts['note']}, residual {facts['residual']:.1e}, min det F "
                  f"{facts['min_det_f']:.3f}, {facts['time_s']:.1f} s, peak "
                  f"{fmt(r['peak_mb'], 4)} MB", flush=True)
    OUT_DIR.mkdir(parents=True, exist_ok=True)
    with open(OUT_DIR / "bunny.csv", "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(BUNNY_COLS)
        for r in rows:
            w.writerow([fmt(r[c], 7) for c in BUNNY_COLS])
    (OUT_DIR / "bunny.txt").write_text("".join(bunny_line(r) + "\n" for r in rows))
    print(f"wrote {OUT_DIR.relative_to(ROOT)}/bunny.csv, bunny.txt in {time.time() - t_all:.0f} s")
    return 0 if rows and all(math.isfinite(r["fem_max_mm"]) for r in rows) else 1


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
    # the indentation's answers come from --indent (merge_indent_answers): kept as they are
    old = (json.loads((OUT_DIR / "answers.json").read_text())
           if (OUT_DIR / "answers.json").exists() else {})
    if "indent" in old:
        answers["indent"] = old["indent"]
        meta["indent_generated_by"] = old.get("meta", {}).get("indent_generated_by",
                                                              "scripts/fem-reference --indent")
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
    """The --check set: cantilever k = 2 P2 (both moduli), compress k = 1 P2 (every strain),
    indent at INDENT_CHECK (P1 and P2, k = 4; snh, straight to d = INDENT_CHECK_DEPTH_MM)."""
    rows = list(cantilever(2, 2)) + list(compress(1, 2))
    values = {f"{r['problem']} {r['quantity']} {r['case']} {r['element']} k={r['level']}": r
              for r in rows}
    for order, k in INDENT_CHECK:
        for r in indent(k, order, "snh", depths_mm=(INDENT_CHECK_DEPTH_MM,)):
            values[f"{r['problem']} {r['quantity']} {r['case']} {r['law']} {r['element']} "
                   f"k={r['level']}"] = r
    return values


def run_check(bless):
    t0 = time.time()
    failures = []
    selftest = kernel_selftest()
    for name, err in selftest.items():
        if not err < 1e-6:
            failures.append(f"kernel self-test {name}: relative difference {err:.1e} > 1e-6")
    lattice_ok = all(box_is_ours((SLAB,) * 3, (k, k, k)) for k in (4, 6))
    if not lattice_ok:
        failures.append("lattice: box() is not our box_tets lattice (indent, k = 4 and 6)")
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
    print(f"FEM CHECK lattice box()=ours_box_tets {'ok' if lattice_ok else 'FAILED'}")
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
    mode.add_argument("--bunny", nargs="+", metavar="FILE",
                      help="exported bunnies (JSON): FEM levels and our field against them")
    mode.add_argument("--indent", action="store_true",
                      help="the slab indented by a sphere: force against depth, and Hertz")
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
    if args.bunny:
        return run_bunny(args.bunny)
    if args.indent:
        return run_indent()
    return run_check(bless=args.bless)


if __name__ == "__main__":
    sys.exit(main())
