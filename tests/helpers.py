"""Solves used across the tests: the subdomain iteration as a linear solver, and Newton."""

import numpy as np
import scipy.linalg
from mpi4py import MPI
from petsc4py import PETSc

import subdomain_contact as sc

#: Systems the helpers made during the current test, destroyed after it (conftest).
SYSTEMS: list[sc.System] = []


def release(comm) -> None:
    """Destroy the systems the helpers made, collect the rest (collective on ``comm``).

    Between the tests (conftest), and inside a test that builds many large scenes: MPI has
    2048 communicators per process, and each body's mesh and spaces hold a few until
    Python frees them.
    """
    import gc

    from petsc4py import PETSc

    for system in SYSTEMS:
        system.destroy()
    SYSTEMS.clear()
    gc.collect()
    PETSc.garbage_cleanup(comm)


def make_system(problem, **options):
    """A system destroyed after the current test."""
    system = sc.System(problem, **options)
    SYSTEMS.append(system)
    return system


def linear_solve(problem, corrector=None, *, rtol=1e-10, solver=None, **options):
    """The whole linear problem by the subdomain iteration alone: (system, inner result).

    One Newton step from the cold state, its linear solve driven directly (so that a failing
    iteration raises :class:`~subdomain_contact.SubdomainConvergenceError` with its history);
    the system then holds the solution. ``solver``: a :class:`~subdomain_contact.Subdomains`
    to use (and inspect after), instead of one made from ``corrector`` and ``options``.
    """
    system = make_system(problem)
    system.reset()
    system.apply_conditions()
    f = system.create_vector()
    system.residual(f)
    system.assemble_jacobian()
    solver = solver or sc.Subdomains(corrector, **options)
    solver.setup(system)
    y, result = solver.solve(f.array_r.copy(), sc.Tolerance(rtol=rtol))
    x = system.state()
    x.array[:] -= y
    system.set_state(x)
    for vec in (f, x):
        vec.destroy()
    return system, result


def snapshot(system, field="temperature"):
    """Body name -> owned values of a scalar field (copies), and the masters."""
    from verification.nodal import field_values

    return field_values(system, field)[1], {k: v.copy() for k, v in system.masters.items()}


def monolithic(system):
    """The monolithic reference of the same system, solved from the cold state.

    From the cold state, not from the subdomain solution it is compared with: Newton would
    find that one converged already and take no step.
    """
    system.reset()
    result = sc.solve(system, sc.Monolithic())
    assert result.iterations >= 1
    return result


def interface_operator(solver) -> np.ndarray:
    """``S`` of a set-up :class:`~subdomain_contact.Subdomains`, dense, column by column."""
    return np.column_stack([solver.apply(e) for e in np.eye(solver.size)])


def preconditioned_condition(problem, *, coarse: bool) -> float:
    """κ(P S) of the interface problem: S and its preconditioner P formed column by column."""
    with sc.System(problem) as system:
        system.reset()
        system.assemble_jacobian()
        solver = sc.Subdomains(krylov=True, coarse=coarse)
        solver.setup(system)
        S = interface_operator(solver)
        P = np.column_stack([solver.precondition(e) for e in np.eye(solver.size)])
    eigenvalues = scipy.linalg.eigvalsh(0.5 * (S + S.T), np.linalg.inv(0.5 * (P + P.T)))
    return float(eigenvalues.max() / eigenvalues.min())


def same_pattern(A: PETSc.Mat, B: PETSc.Mat) -> bool:
    """Whether two AIJ matrices store the same entries (collective).

    The count of stored entries is not enough: a contact that opens here and closes there
    may drop as many entries as it adds, and a factorisation reused on such a pattern solves
    another matrix.
    """
    if A.getSize() != B.getSize() or A.getOwnershipRange() != B.getOwnershipRange():
        return False
    a, b = A.getValuesCSR(), B.getValuesCSR()
    same = bool(np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]))
    return bool(A.getComm().tompi4py().allreduce(same, op=MPI.LAND))
