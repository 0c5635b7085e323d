"""Shared fixtures and helpers: every test runs on MPI.COMM_WORLD, serially or under mpiexec."""

import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)
import pytest
from mpi4py import MPI

from verification.cases import two_plates_scene


@pytest.fixture(scope="session")
def comm() -> MPI.Comm:
    return MPI.COMM_WORLD


@pytest.fixture(scope="session")
def plates(comm):
    """The two plates, 4 element layers each, 4 rows along the contact (quadrilaterals)."""
    return two_plates_scene(4, 4, comm=comm)


@pytest.fixture(scope="session")
def plates_fine(comm):
    """The two plates, 8 layers and 6 rows, triangles: a second mesh for the same checks."""
    return two_plates_scene(8, 6, quads=False, comm=comm)


@pytest.fixture(autouse=True)
def collect_garbage(comm):
    """After each test, with every rank at the same point: free what it left behind.

    The systems the helpers made are destroyed (collectively); Python collects the rest and
    petsc4py hands parallel PETSc objects to PETSc's garbage, which ``garbage_cleanup``
    destroys collectively (a MUMPS factorisation's destruction is collective), so that
    communicators do not run out.
    """
    yield
    from helpers import release

    release(comm)


@pytest.fixture
def shared_tmp(tmp_path, comm):
    """One temporary folder that every rank agrees on."""
    from pathlib import Path

    return Path(comm.bcast(str(tmp_path), root=0))


def pytest_sessionfinish(session, exitstatus):
    """Free what the tests left to petsc4py while MPI is alive, on every rank together."""
    import gc

    from petsc4py import PETSc

    gc.collect()
    PETSc.garbage_cleanup(MPI.COMM_WORLD)


def pytest_assertion_pass(item, lineno, orig, expl):
    """With SC_ASSERTIONS=<file>: record every passing assertion with its values."""
    import os

    path = os.environ.get("SC_ASSERTIONS")
    if path:
        # one write with O_APPEND: whole records when two test workers share a rank's file
        fd = os.open(f"{path}.{MPI.COMM_WORLD.rank}", os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            os.write(fd, f"@@ {item.nodeid}:{lineno}: {orig}\n{expl}\n".encode())
        finally:
            os.close(fd)
