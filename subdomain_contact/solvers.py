"""PETSc solver presets, as named read-only option sets, and KSP construction with a prefix."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from types import MappingProxyType

import numpy as np
import scipy.linalg
from mpi4py import MPI
from petsc4py import PETSc

__all__ = [
    "AMD_ROWS",
    "BLOCK_LOW_RANK",
    "DIRECT",
    "FIELDSPLIT_DIRECT",
    "FIELDSPLIT_SINGLE",
    "FIELD_SWEEP",
    "REFACTORISATION_MARGIN",
    "SWEEP_DIRECT",
    "THERMOELECTRIC_MECHANICAL",
    "RowScaledKrylov",
    "available_memory",
    "columns_apply",
    "columns_mult",
    "default_option",
    "destroy",
    "factorisation_memory",
    "factorise",
    "fgmres_columns",
    "fits_freed",
    "make_ksp",
    "node_memory",
    "ordered",
    "ordering",
    "refactorisation_memory",
    "refactorisation_shortfall",
    "refuse_factorisation",
    "refuse_refactorisation",
    "set_up",
    "sweepable",
]

#: Sparse direct solve by MUMPS (the factorisation is kept and reused).
DIRECT: Mapping[str, str] = MappingProxyType(
    {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
)

#: The coupled problem's fields in two splits (for :data:`FIELDSPLIT_DIRECT`): T and φ, which
#: couple both ways everywhere (Joule heat, σ(T)), then u, which depends on them everywhere
#: (thermal expansion) while they depend on u only on the contacts (conductances of the
#: pressure). The Jacobian is block lower triangular in this order but for those contact rows.
THERMOELECTRIC_MECHANICAL: Mapping[str, tuple[str, ...]] = MappingProxyType(
    {"thermoelectric": ("temperature", "potential"), "displacement": ("displacement",)}
)


def sweepable(fields: Sequence[str]) -> bool:
    """Whether ``fields`` fill both splits of :data:`THERMOELECTRIC_MECHANICAL`: T or φ, and u."""
    return all(set(f) & set(fields) for f in THERMOELECTRIC_MECHANICAL.values())


#: GMRES (right-preconditioned: the true residual, rows in W, A and N) on one block
#: Gauss-Seidel sweep over named splits (PETSc's multiplicative ``fieldsplit``): the frame of
#: the field-split presets, to which each adds its splits' solves (``fieldsplit_<name>_``).
FIELD_SWEEP: Mapping[str, str] = MappingProxyType(
    {
        "ksp_type": "gmres",
        "ksp_gmres_restart": "200",
        "ksp_pc_side": "right",
        "ksp_rtol": "1e-12",
        "ksp_max_it": "1000",
        "pc_type": "fieldsplit",
        "pc_fieldsplit_type": "multiplicative",
    }
)

#: The coupled problem's monolithic solve by two smaller factorisations: GMRES preconditioned
#: by one block Gauss-Seidel sweep over :data:`THERMOELECTRIC_MECHANICAL` (pass it as
#: ``Monolithic(splits=...)``), each split's block factorised by MUMPS. The sweep is exact but
#: for the contacts' dependence on u, so GMRES needs few iterations (a low-rank error), and two
#: factorisations of 2 and 3 unknowns per node cost less than one of 5 (about (2³ + 3³)/5³ of
#: the work of a 3D one, (2² + 3²)/5² of its memory). The collector bar slot at 203,925 DOFs,
#: constant setup, monolithic Newton from 1233 K, 2 ranks (one run each, 2026-11-29): 16
#: Newton steps, 4–8 GMRES iterations a step (33 at one limited step), 244.7 s against MUMPS
#: on the whole 381.4 s; MUMPS's memory 376 + 812 MB on its largest rank against 2,196 MB.
#: Nested from 11.5k DOFs (the demo's `--linear split`): 101.8 s against 166.5 s
#: (docs/collector_bar_slot.md).
FIELDSPLIT_DIRECT: Mapping[str, str] = MappingProxyType(
    FIELD_SWEEP
    | {
        f"fieldsplit_{split}_{k}": v
        for split in THERMOELECTRIC_MECHANICAL
        for k, v in DIRECT.items()
    }
)

#: Block low-rank factors (MUMPS's BLR, ICNTL(35) = 2, in the factorisation and the solve;
#: the UCFS variant, ICNTL(36) = 1, compressing before the updates) at a dropping threshold
#: CNTL(7) of 1e-6: about 17 times single precision's ε (6e-8), so the factors' error stays
#: of the order the precision leaves. Measured on the collector bar slot at 1,217,760 DOFs
#: (2 ranks, 2026-12-03, one run each): the two splits factorised again in place in 47–49 s
#: against 115–121 s full-rank (analysis included; the full-rank factors left no room to
#: refactorise in place), 12–21 GMRES iterations a step and one solve on from the iterate
#: (:meth:`Monolithic._krylov <subdomain_contact.monolithic.Monolithic._krylov>`), the same
#: Newton residuals to two digits. At 1e-4 it was not reliable: 424 and 337 iterations at
#: two steps.
BLOCK_LOW_RANK: Mapping[str, str] = MappingProxyType(
    {"mat_mumps_icntl_35": "2", "mat_mumps_icntl_36": "1", "mat_mumps_cntl_7": "1e-6"}
)

#: :data:`FIELDSPLIT_DIRECT` with each split factorised in single precision (MUMPS's own,
#: PETSc's ``pc_precision``) and block low-rank (:data:`BLOCK_LOW_RANK`): about half the
#: factors' memory and work by the precision, less than half the rest by BLR, where the
#: double ones do not fit (the collector bar slot at 1.14M DOFs: two ranks past 11 GB each).
#: GMRES on the true residual (rtol 1e-12) makes up for both: the slot at 17,335 DOFs, nested
#: from 5,595, 5–8 iterations a step against 1–4 (single, full-rank), the same voltage drop
#: (179.64 mV); at 1.2M DOFs the fine level in 639 s against 1,059 s (single, full-rank).
#: Flexible GMRES since 2026-12-07 (:class:`RowScaledKrylov` says why): the row of four 3D
#: blocks at 1,011,295 DOFs (2 ranks, one run each) took 13 full Newton steps, 488
#: iterations, 610.5 s, where GMRES's first full steps broke down at the second (reason -5)
#: and limited steps took 11, 477 iterations, 840.6 s.
FIELDSPLIT_SINGLE: Mapping[str, str] = MappingProxyType(
    FIELDSPLIT_DIRECT
    | {"ksp_type": "fgmres"}
    | {
        f"fieldsplit_{split}_{k}": v
        for split in THERMOELECTRIC_MECHANICAL
        for k, v in ({"pc_precision": "single"} | BLOCK_LOW_RANK).items()
    }
)

#: One sweep of :data:`FIELDSPLIT_DIRECT`, no Krylov: an approximate inverse that is exact but
#: for the contacts' dependence on u (the sparse strip corrector's solve, inside the
#: interface Krylov).
SWEEP_DIRECT: Mapping[str, str] = MappingProxyType(
    {k: v for k, v in FIELDSPLIT_DIRECT.items() if not k.startswith("ksp_")}
    | {"ksp_type": "preonly"}
)

#: Rows up to which a 2D mesh's matrix that is factorised again and again is ordered by
#: approximate minimum degree: see :func:`ordering`.
AMD_ROWS = 100_000

# Reproducible Krylov solves. PETSc's VecMDot (GMRES's orthogonalisation) goes through BLAS
# gemv by default, whose kernels round differently with the alignment of the vectors in
# memory: the same GMRES + GAMG body solve then differed between two runs of one script, and
# between two solves in one process, at 1e-8 (GAMG's aggregation turns the round-off into a
# different preconditioner), which Newton's path on an exponential closure amplifies.
# PETSc's own unrolled kernel rounds the same way wherever the vectors lie: the row of four
# 3D blocks at 11k DOFs repeats its Newton residuals bit for bit (three runs, serial and on 2
# ranks; with gemv two runs differed), no slower (31k DOFs: 24.3 s against 29.3 s). At 1.01M
# DOFs on 2 ranks another source remains (two runs parted at step 4; the suspect, MUMPS on a
# strip that spans ranks: README). Read when a vector is created; a user's own
# ``-vec_mdot_use_gemv`` is kept.
if not PETSc.Options().hasName("vec_mdot_use_gemv"):
    PETSc.Options().setValue("vec_mdot_use_gemv", False)


def ordering(dim: int, rows: int, *, again: bool) -> int | None:
    """MUMPS's fill-reducing ordering, ICNTL(7), for a matrix of a mesh of dimension ``dim``.

    In 2D, METIS's nested dissection costs more than the factorisation it orders, while
    approximate minimum degree (0) orders in a tenth of the time for more factorisation work
    (Laplacian, P1, one rank, 2026-11-25; analysis, then factorisation: 66k rows 0.36 + 0.17 s
    with METIS, 0.03 + 0.19 s with AMD; 526k rows 3.1 + 1.4 s, 0.21 + 2.3 s; 1.05M rows 7.7 +
    4.9 s, 0.6 + 10.2 s). A factorisation made again on new values keeps its ordering, so for
    a matrix factorised ``again`` (it depends on the state) above :data:`AMD_ROWS` rows
    METIS's cheaper factorisations win back its analysis within a few Newton steps (the
    monolithic Newton of ``hot_squeezed_bars``, T and u, 9 factorisations: 197k rows, 18.1
    and 18.7 s with METIS, 19.2 and 22.0 s with AMD; 100k rows, even within the noise). In 3D
    nested dissection wins outright (69k rows: 3.4 s in all with METIS, 9.2 s with AMD).

    Returns:
        0 (AMD) for a 2D mesh's matrix factorised once, or of at most :data:`AMD_ROWS` rows;
        None otherwise (MUMPS's own choice: METIS here). ``-<prefix>mat_mumps_icntl_7`` wins
        over both.
    """
    return 0 if dim == 2 and (rows <= AMD_ROWS or not again) else None


def ordered(options: Mapping[str, str], dim: int, rows: int, *, again: bool) -> Mapping[str, str]:
    """``options`` with :func:`ordering` on each MUMPS solve among them.

    Every ``<p>pc_factor_mat_solver_type: mumps`` (a direct solve; BDDC's Dirichlet, Neumann
    and coarse solves) and ``<p>mat_solver_type: mumps`` (BDDC's deluxe factorisation,
    ``sub_schurs_``) gets ``<p>mat_mumps_icntl_7``, unless ``options`` give it.
    """
    chosen = ordering(dim, rows, again=again)
    if chosen is None:
        return options
    added = {
        key.removesuffix("pc_factor_mat_solver_type").removesuffix("mat_solver_type")
        + "mat_mumps_icntl_7": str(chosen)
        for key, value in options.items()
        if key.endswith("mat_solver_type") and value == "mumps"
    }
    return MappingProxyType({**added, **options})


def make_ksp(
    A: PETSc.Mat,
    prefix: str,
    options: Mapping[str, str],
    *,
    setup: bool = True,
    splits: Sequence[tuple[str, PETSc.IS]] = (),
) -> PETSc.KSP:
    """KSP on ``A`` configured from ``options`` under its own ``prefix``; set up (factorised).

    With ``setup=False`` the factorisation waits for the first ``setUp`` or solve (for a
    matrix not assembled yet). ``splits``: the named index sets of a ``fieldsplit``
    preconditioner (their ``fieldsplit_<name>_`` options among ``options``).

    Options already in the PETSc database under ``prefix`` (from the command line) win;
    ``options`` are removed from the database once the KSP is set up (or configured, with
    ``setup=False``), so that the next KSP of the same prefix gets its own. MUMPS reads its
    ``mat_mumps_icntl_*`` when it factorises: those of a direct solve go to its factor matrix.
    """
    database = PETSc.Options()
    added = [prefix + key for key in options if not database.hasName(prefix + key)]
    for key, value in options.items():
        if prefix + key in added:
            database.setValue(prefix + key, value)
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOptionsPrefix(prefix)
    ksp.setOperators(A)
    ksp.setFromOptions()
    pc = ksp.getPC()
    if splits:
        pc.setFieldSplitIS(*splits)
    if pc.getType() in ("lu", "cholesky") and pc.getFactorSolverType() == "mumps":
        pc.setFactorSetUpSolverType()
        for key, value in options.items():
            if key.startswith("mat_mumps_icntl_") and prefix + key in added:
                pc.getFactorMatrix().setMumpsIcntl(int(key.rsplit("_", 1)[1]), int(value))
    if setup:
        # with its splits: MUMPS reads their options (ICNTL(7), ``pc_precision``) when it
        # factorises them, which must happen while those are in the database
        set_up(ksp)
    for name in added:
        database.delValue(name)
    return ksp


def set_up(ksp: PETSc.KSP) -> None:
    """Set ``ksp`` up (factorise it), a field split's blocks at once.

    PCFIELDSPLIT leaves each block's set-up (its factorisation) to the first solve.
    """
    ksp.setUp()
    pc = ksp.getPC()
    for sub in pc.getFieldSplitSubKSP() if pc.getType() == "fieldsplit" else ():
        sub.setUp()


def default_option(name: str, value: str) -> bool:
    """Set a PETSc option unless the user has (command line, database); whether it was set."""
    options = PETSc.Options()
    if options.hasName(name):
        return False
    options.setValue(name, value)
    return True


class _ScaledRows:
    """``D A`` as a PETSc Python matrix (``D``: a diagonal, as a vector)."""

    def __init__(self, A: PETSc.Mat, d: PETSc.Vec) -> None:
        self.A, self.d = A, d

    def mult(self, _: PETSc.Mat, x: PETSc.Vec, y: PETSc.Vec) -> None:
        self.A.mult(x, y)
        y.pointwiseMult(y, self.d)


class _Unscaled:
    """``M⁻¹ D⁻¹`` as a PETSc Python preconditioner, ``M⁻¹`` a set-up PC on ``A``.

    ``first``: ``M⁻¹ b̂ / ‖D b̂‖`` computed before the solve, given for the first application
    where its argument is the Krylov method's first basis vector ``D b̂ / ‖D b̂‖`` (checked).
    """

    def __init__(self, pc: PETSc.PC, d: PETSc.Vec) -> None:
        self.pc, self.d = pc, d
        self.work, self.basis = d.duplicate(), d.duplicate()
        self.first: PETSc.Vec | None = None

    def apply(self, _: PETSc.PC, x: PETSc.Vec, y: PETSc.Vec) -> None:
        first, self.first = self.first, None
        if first is not None:
            self.work.waxpy(-1.0, x, self.basis)
            if self.work.norm(PETSc.NormType.INFINITY) <= 1e-12:  # |basis| ≤ 1: absolute
                first.copy(y)
                return
        self.work.pointwiseDivide(x, self.d)
        self.pc.apply(self.work, y)

    def destroy(self, _: PETSc.PC) -> None:
        """Free its vectors (called by PETSc as the preconditioner is destroyed)."""
        destroy(self.work, self.basis)


class RowScaledKrylov:
    """A flexible Krylov solve of ``A x = b`` with each row weighed, right-preconditioned.

    Solves ``D A x = D b`` (``D`` diagonal, set per solve) preconditioned on the right by
    ``M⁻¹ D⁻¹``, where ``M⁻¹`` is ``ksp``'s set-up preconditioner on ``A`` (ksp itself is
    not solved: its tolerances and preconditioner are used), so the test is on the true
    residual weighed row by row: fields of different units (W, A, N) each count at their own
    scale. Flexible GMRES keeps every application of ``M⁻¹`` it made, so its residual stays
    the true one to double precision where ``M⁻¹`` is applied in single precision (Arioli &
    Duff, 2009, *Using FGMRES to obtain backward stability in mixed precision*, ETNA 33):
    left-preconditioned GMRES's estimate of the preconditioned residual drifted from the true
    one by single precision's round-off, 1e4-1e5 times the tolerance on the row of four 3D
    blocks, and GMRES on the right, which applies ``M⁻¹`` once more to its combination of
    the basis, left a true residual of 0.45 of the right-hand side where it claimed 1e-12
    (a chain of 4,000 springs, single-precision LU).
    """

    def __init__(self, ksp: PETSc.KSP, A: PETSc.Mat, restart: int) -> None:
        comm = A.getComm()
        self.d = A.createVecRight()
        self.x, self.b, self.first = A.createVecRight(), A.createVecRight(), A.createVecRight()
        self.operator = PETSc.Mat().createPython(A.getSizes(), _ScaledRows(A, self.d), comm=comm)
        self.operator.setUp()
        self.context = _Unscaled(ksp.getPC(), self.d)
        pc = PETSc.PC().createPython(self.context, comm=comm)
        self.ksp = PETSc.KSP().create(comm)
        self.ksp.setType("fgmres")  # GMRES on the right took 0.45 of the rhs for 1e-12
        self.ksp.setGMRESRestart(restart)
        self.ksp.setPC(pc)
        pc.destroy()
        self.ksp.setOperators(self.operator)
        self.ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
        self.ksp.setTolerances(rtol=ksp.getTolerances()[0], max_it=ksp.getTolerances()[3])
        # Classical Gram-Schmidt refined where it loses orthogonality (PETSc's default never
        # refines): on the row of four 3D blocks at 1.01M DOFs three body solves ran their
        # whole restart of 100 without meeting 1e-12, then met it 2-5 iterations after it.
        prefix = (ksp.getOptionsPrefix() or "") + "rows_"
        self.ksp.setOptionsPrefix(prefix)
        key = prefix + "ksp_gmres_cgs_refinement_type"
        added = default_option(key, "refine_ifneeded")
        self.ksp.setFromOptions()
        if added:
            PETSc.Options().delValue(key)

    def solve(
        self, b: PETSc.Vec, weigh: Callable[[PETSc.Vec, PETSc.Vec], np.ndarray], rtol: float
    ) -> PETSc.Vec:
        """``x`` of ``A x = b`` to ``‖D (b - A x)‖₂ ≤ rtol ‖D b‖₂``, ``D = diag(weigh(b, M⁻¹ b))``.

        ``M⁻¹ b`` is the method's first application, made here to give the weights (an
        estimate of the solution) and handed to it. Returns the solution vector (owned by
        this object: copy it); the iteration count and reason are ``self.ksp``'s.
        """
        first = self.first
        self.context.pc.apply(b, first)
        self.d.array[:] = weigh(b, first)
        self.b.pointwiseMult(b, self.d)
        norm = self.b.norm()
        if norm > 0:
            first.scale(1.0 / norm)
            self.b.copy(self.context.basis)
            self.context.basis.scale(1.0 / norm)
            self.context.first = first
        self.ksp.setTolerances(rtol=rtol)
        self.ksp.solve(self.b, self.x)
        self.context.first = None
        return self.x

    def destroy(self) -> None:
        """Free its PETSc objects (not ``ksp``'s)."""
        destroy(self.ksp, self.operator, self.d, self.x, self.b, self.first)


def _dense(values: np.ndarray, A: PETSc.Mat) -> PETSc.Mat:
    """Columns on ``A``'s owned rows as a dense PETSc matrix of A's row layout (a copy)."""
    rows = A.getSizes()[0]
    return PETSc.Mat().createDense(
        (rows, (PETSc.DECIDE, values.shape[1])), array=np.asfortranarray(values), comm=A.getComm()
    )


def columns_mult(A: PETSc.Mat, X: np.ndarray) -> np.ndarray:
    """``A X`` for columns ``X`` on A's owned rows (one sparse-dense product)."""
    B = _dense(X, A)
    P = A.matMult(B)
    out = P.getDenseArray(readonly=True).copy()
    destroy(B, P)
    return out


def columns_apply(pc: PETSc.PC, X: np.ndarray) -> np.ndarray:
    """``M⁻¹ X``, a set-up preconditioner applied to every column at once.

    ``PCMatApply``: a factorisation's ``MatMatSolve``, for a field split one block sweep.
    """
    A = pc.getOperators()[1]
    B = _dense(X, A)
    Y = B.duplicate()
    pc.matApply(B, Y)
    out = Y.getDenseArray(readonly=True).copy()
    destroy(B, Y)
    return out


def fgmres_columns(
    A: PETSc.Mat,
    pc: PETSc.PC,
    b: np.ndarray,
    weights: np.ndarray,
    rtol: np.ndarray,
    restart: int,
    max_it: int,
    first: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:class:`RowScaledKrylov` on every column of ``A X = B`` at once, in lockstep.

    Column j is solved by its own flexible GMRES on ``D_j A x = D_j b_j``, right-preconditioned
    by ``M⁻¹ D_j⁻¹`` (``D_j = diag(weights[:, j])``), to ``‖D_j (b_j − A x_j)‖₂ ≤ rtol_j
    ‖D_j b_j‖₂`` by its residual estimate, as PETSc's FGMRES stops (the estimate follows the
    true residual down to the round-off of computing it; below, it falls on alone: a nearly
    floating block at 74,580 DOFs, asked 1e-12, estimated 5e-14 where the true residual
    stayed at 1e-11, and restarting on the true one never ended, so the caller's test
    refines instead, :meth:`~subdomain_contact.body.Body._solve_split`); but each iteration applies
    ``M⁻¹`` to every column still going in one call (:func:`columns_apply`), and ``A`` in one
    product. A factorised sweep's triangular solves on several right-hand sides cost little
    more than on one (MUMPS's MatMatSolve, BLAS 3): on the row of four 3D blocks, 5-8 coarse
    columns a third of a sweep each. PETSc's ``KSPMatSolve`` has a method of its own for
    several columns only in HPDDM (not in this build); otherwise it solves them one by one.
    Gram-Schmidt: classical, twice (each column's basis stays orthogonal to round-off). A
    column whose estimate has not met its tolerance after ``restart`` iterations restarts
    from its true residual, up to ``max_it`` iterations in all.

    ``b``, ``weights``: owned rows × columns; ``first``: ``M⁻¹ b``, computed by the caller for
    the weights (the first application). Returns ``X``, each column's iteration count, and
    whether it met its tolerance.
    """
    comm = A.getComm().tompi4py()

    def summed(values: np.ndarray) -> np.ndarray:
        if comm.size > 1:
            comm.Allreduce(MPI.IN_PLACE, values, op=MPI.SUM)
        return values

    def norms(V: np.ndarray) -> np.ndarray:
        return np.sqrt(summed(np.einsum("nc,nc->c", V, V)))

    n, m = b.shape
    x, iterations = np.zeros((n, m)), np.zeros(m, dtype=np.int64)
    target = rtol * norms(weights * b)
    met = target == 0.0  # a zero right-hand side: x = 0
    going, start = ~met, True
    while going.any():
        cols = np.flatnonzero(going)
        D = weights[:, cols]
        r = D * (b[:, cols] if start else b[:, cols] - columns_mult(A, x[:, cols]))
        beta = norms(r)
        if not start:  # the true residual met the tolerance at the restart
            met[cols[beta <= target[cols]]] = True
            going &= ~met
            keep = beta > target[cols]
            cols, D, r, beta = cols[keep], D[:, keep], r[:, keep], beta[keep]
            if not cols.size:
                break
        mc = cols.size
        V, Z = np.empty((restart + 1, n, mc)), np.empty((restart, n, mc))
        H, g = np.zeros((restart + 1, restart, mc)), np.zeros((restart + 1, mc))
        cs, sn = np.zeros((restart, mc)), np.zeros((restart, mc))
        V[0], g[0] = r / beta, beta
        on, steps = np.ones(mc, dtype=bool), np.zeros(mc, dtype=np.int64)
        for k in range(restart):
            c = np.flatnonzero(on)
            if not c.size:
                break
            if start and k == 0:  # V₀ = D b / β: M⁻¹ D⁻¹ V₀ = M⁻¹ b / β
                Z[0] = first[:, cols] / beta
            else:
                Z[k][:, c] = columns_apply(pc, V[k][:, c] / D[:, c])
            w = D[:, c] * columns_mult(A, Z[k][:, c])
            for _ in range(2):
                h = summed(np.einsum("jnc,nc->jc", V[: k + 1][:, :, c], w))
                w -= np.einsum("jnc,jc->nc", V[: k + 1][:, :, c], h)
                H[: k + 1, k, c] += h
            H[k + 1, k, c] = norms(w)
            V[k + 1][:, c] = w / np.where(H[k + 1, k, c] > 0, H[k + 1, k, c], 1.0)
            for i in range(k):  # the earlier rotations, then this one
                upper, lower = H[i, k, c], H[i + 1, k, c]
                H[i, k, c] = cs[i, c] * upper + sn[i, c] * lower
                H[i + 1, k, c] = -sn[i, c] * upper + cs[i, c] * lower
            rho = np.hypot(H[k, k, c], H[k + 1, k, c])
            cs[k, c], sn[k, c] = H[k, k, c] / rho, H[k + 1, k, c] / rho
            H[k, k, c], H[k + 1, k, c] = rho, 0.0
            g[k + 1, c], g[k, c] = -sn[k, c] * g[k, c], cs[k, c] * g[k, c]
            steps[c] += 1
            iterations[cols[c]] += 1
            done = np.abs(g[k + 1, c]) <= target[cols[c]]
            met[cols[c[done]]] = True
            on[c[done | (iterations[cols[c]] >= max_it)]] = False
        for i, j in enumerate(cols):
            kk = steps[i]
            y = scipy.linalg.solve_triangular(H[:kk, :kk, i], g[:kk, i])
            x[:, j] += Z[:kk, :, i].T @ y
        going &= ~met & (iterations < max_it)
        start = False
    return x, iterations, met


def factorise(
    A: PETSc.Mat,
    prefix: str,
    what: str,
    ksp: PETSc.KSP | None = None,
    *,
    dim: int = 3,
    again: bool = True,
    advice: str | None = None,
) -> PETSc.KSP:
    """A MUMPS factorisation of ``A``: a new KSP, or ``ksp`` factorised again on A's values.

    ``dim``: the topological dimension of the mesh behind ``A``; ``again``: whether it will be
    factorised again on new values (:func:`ordering`). ``advice``: where given, a new
    factorisation is first weighed against the memory its node has left
    (:func:`refuse_factorisation`) and refused with this advice. A workspace that falls
    short is relaxed (:func:`set_up_relaxed`).

    Raises:
        RuntimeError: The factorisation failed otherwise, naming ``what`` and the reason.
        MemoryError: With ``advice``, the new factorisation would not fit (collective).
    """
    options = ordered(DIRECT, dim, A.getSize()[0], again=again)
    if ksp is None and advice is not None:
        refuse_factorisation(A, prefix, options, what, advice)
    ksp, relaxation = set_up_relaxed(A, prefix, options, ksp)
    reason = ksp.getPC().getFailedReason()
    if reason != 0:
        ksp.destroy()
        raise RuntimeError(
            f"{what}: factorisation failed (PETSc PC reason {reason}, MUMPS workspace relaxed "
            f"to {relaxation['']} %)"
        )
    return ksp


#: MUMPS's workspace relaxation ICNTL(14) [%]: its default, and the most
#: :func:`set_up_relaxed` doubles it to.
RELAXATION = (20, 1600)


def set_up_relaxed(
    A: PETSc.Mat,
    prefix: str,
    options: Mapping[str, str],
    ksp: PETSc.KSP | None = None,
    *,
    splits: Sequence[tuple[str, PETSc.IS]] = (),
) -> tuple[PETSc.KSP, dict[str, int]]:
    """A KSP on ``A`` (:func:`make_ksp`), or ``ksp`` set up again on A's values, factorised.

    While MUMPS's workspace estimate falls short on a factorisation (INFOG(1) = −9, PETSc's
    FACTOR_OUTMEMORY), the KSP's own or a split's, the KSP is made again with that
    factorisation's relaxation ICNTL(14) doubled, up to :data:`RELAXATION`'s most: numerical
    pivoting at a stiff or opening contact delays pivots beyond the analysis's estimate (two
    3D blocks at h = 1e10 on 2 ranks: 20 % fails, 200 % factorises; the thermoelectric split
    of the collector bar slot's sparse strip failed once in five test runs on 2 ranks).

    Returns:
        The KSP, whose factorisations' failed reasons are the caller's to read, and the
        relaxation of each by split name ("" for the KSP's own) [%].
    """
    names = [name for name, _ in splits] or [""]
    relaxation = dict.fromkeys(names, RELAXATION[0])
    if ksp is None:
        ksp = make_ksp(A, prefix, options, splits=splits)
    else:
        ksp.setOperators(A)
        set_up(ksp)
    while True:
        pcs = (
            [sub.getPC() for sub in ksp.getPC().getFieldSplitSubKSP()] if splits else [ksp.getPC()]
        )
        short = [
            name
            for name, pc in zip(names, pcs, strict=True)
            if pc.getFailedReason() == PETSc.PC.FailedReason.FACTOR_OUTMEMORY
            and relaxation[name] < RELAXATION[1]
        ]
        if not short:
            return ksp, relaxation
        for name in short:
            relaxation[name] = min(2 * relaxation[name], RELAXATION[1])
        relaxed = {
            (f"fieldsplit_{name}_" if name else "") + "mat_mumps_icntl_14": str(value)
            for name, value in relaxation.items()
            if value > RELAXATION[0]
        }
        ksp.destroy()
        ksp = make_ksp(A, prefix, {**options, **relaxed}, splits=splits)


#: A MUMPS factorisation made again on new values needs, beside what stays resident, about the
#: memory it used the last time (INFO(22)): the sparse strip of the collector bar slot at
#: 1.14M DOFs (2 ranks, block low-rank) peaked 7.6 GiB above the node's resident set before
#: it, for INFO(22) summing to 7.2 GiB (1.05 times); 1.25 leaves room for the copies of its
#: matrix made with it.
REFACTORISATION_MARGIN = 1.25


def available_memory() -> float | None:
    """Memory the node can still give [bytes] (Linux's MemAvailable), None where unknown."""
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return 1024.0 * float(line.split()[1])
    except OSError:
        pass
    return None


def refactorisation_memory(ksp: PETSc.KSP, comm: MPI.Comm) -> tuple[float, float | None]:
    """What factorising ``ksp``'s matrix again needs on the busiest node, and what it has.

    Returns:
        (bytes needed: the node's ranks' INFO(22) of the last factorisation times
        :data:`REFACTORISATION_MARGIN`, bytes available on that node or None where unknown),
        the same on every rank.
    """
    factors = _factors(ksp)
    mumps = bool(factors) and all(f.getType() == "mumps" for f in factors)  # else not known
    used = sum(1e6 * f.getMumpsInfo(22) for f in factors) if mumps else 0.0  # MUMPS's MB
    need, available = node_memory(REFACTORISATION_MARGIN * used, comm)
    return need, available if mumps else None


def node_memory(need: float, comm: MPI.Comm) -> tuple[float, float | None]:
    """The node shortest of memory where each rank needs ``need`` bytes (collective).

    Returns (the sum of its ranks' needs, its available bytes or None where unknown), the same
    on every rank.
    """
    node = comm.Split_type(MPI.COMM_TYPE_SHARED)
    total = node.allreduce(need)
    available = node.bcast(available_memory() if node.rank == 0 else None, root=0)
    node.Free()
    shortest = available - total if available is not None else np.inf
    worst = comm.allreduce((shortest, comm.rank), op=MPI.MINLOC)[1]
    return comm.bcast((total, available), root=worst)


def _factors(ksp: PETSc.KSP) -> list[PETSc.Mat]:
    """The factor matrices of a direct solve, or of each split of a ``fieldsplit`` one."""
    pc = ksp.getPC()
    if pc.getType() == "fieldsplit":
        return [f for sub in pc.getFieldSplitSubKSP() for f in _factors(sub)]
    return [pc.getFactorMatrix()] if pc.getType() in ("lu", "cholesky") else []


def refactorisation_shortfall(ksp: PETSc.KSP, comm: MPI.Comm) -> str | None:
    """Why factorising ``ksp``'s matrix again would not fit; None where it fits.

    The words say what it needs and what the node shortest of memory has. Collective on
    ``comm``. Call it before the matrix takes new values: after, a solve with the old KSP
    would have PETSc factorise it again unasked.
    """
    need, available = refactorisation_memory(ksp, comm)
    if available is None or need <= available:
        return None
    return (
        f"factorising it again needs about {need / 1e9:.3g} GB on a node (MUMPS INFO(22) of "
        f"its last factorisation, times {REFACTORISATION_MARGIN}) where {available / 1e9:.3g} "
        "GB is available"
    )


def fits_freed(ksp: PETSc.KSP, comm: MPI.Comm, times: float = 1.0) -> bool:
    """Whether ``times`` the memory of factorising ``ksp``'s matrix again fits, its factors freed.

    The need is :func:`refactorisation_memory`'s; collective.

    ``times``: the new factorisation against the last one (2 for double precision after
    single, the whole strip against its sweep).
    """
    need, available = refactorisation_memory(ksp, comm)
    return available is None or times * need <= available + need / REFACTORISATION_MARGIN


def factorisation_memory(A: PETSc.Mat, prefix: str, options: Mapping[str, str]) -> float:
    """MUMPS's estimate of what factorising ``A`` needs on this rank [bytes], by its analysis.

    The factorisation is asked with its working memory capped at 1 MB (ICNTL(23)): MUMPS
    analyses, finds that the cap is too small (INFOG(1) = −19) and stops before it allocates
    anything; INFO(15), its estimate of the in-core factorisation with the relaxation
    ICNTL(14), stays (a 3D Laplacian of 69k rows, one rank: 596 MB estimated, 500 MB used by
    the factorisation itself, INFO(22); the capped call took 0.63 s, the factorisation 2.9 s).
    An analysis alone would serve as well, but petsc4py does not offer MatLUFactorSymbolic.
    Collective on ``A``'s communicator.
    """
    ksp = make_ksp(A, prefix, options, setup=False)  # its MUMPS factor matrix made
    factor = ksp.getPC().getFactorMatrix()
    factor.setMumpsIcntl(23, 1)
    ksp.setUp()
    need = 1e6 * factor.getMumpsInfo(15)  # MUMPS's MB
    ksp.destroy()
    return need


def refuse_factorisation(
    A: PETSc.Mat, prefix: str, options: Mapping[str, str], what: str, advice: str
) -> None:
    """A MemoryError naming ``what`` and ``advice`` where A's first factorisation would not fit.

    Weighs :func:`factorisation_memory` on the node shortest of memory (:func:`node_memory`)
    before MUMPS allocates its factors, where the operating system would kill a rank instead
    (the row of four 3D blocks at 1.01M DOFs: a body whose GMRES failed factorised whole took
    the node to 0 GB available). Collective on ``A``'s communicator.
    """
    comm = A.getComm().tompi4py()
    need, available = node_memory(factorisation_memory(A, prefix, options), comm)
    if available is not None and need > available:
        raise MemoryError(
            f"{what}: its factorisation needs about {need / 1e9:.3g} GB on a node (MUMPS's "
            f"estimate after its analysis, INFO(15)) where {available / 1e9:.3g} GB is "
            f"available. Try {advice}"
        )


def refuse_refactorisation(ksp: PETSc.KSP, comm: MPI.Comm, what: str, advice: str) -> None:
    """A MemoryError naming ``what`` and ``advice`` where a new factorisation would not fit.

    Said before the kernel kills a rank (:func:`refactorisation_shortfall`); collective.
    """
    shortfall = refactorisation_shortfall(ksp, comm)
    if shortfall is not None:
        raise MemoryError(f"{what}: {shortfall}. Try {advice}")


def destroy(*objects: PETSc.Object | None) -> None:
    """Destroy PETSc objects at once (collective on their communicators).

    Does nothing once PETSc is finalised (at interpreter exit), when petsc4py frees them.
    """
    if PETSc.Sys.isFinalized():
        return
    for obj in objects:
        if obj is not None:
            obj.destroy()
