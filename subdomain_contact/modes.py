"""A body's kernel modes: the constants of T and φ, the rigid motions of u.

They span what a body's matrix cannot see without its conditions: the coarse space of the
interface Krylov is made of them (on the masters), and so is the near-null space that
smoothed-aggregation AMG needs on a body solved iteratively (on the body's DOFs).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt
from mpi4py import MPI
from petsc4py import PETSc

__all__ = ["Mode", "centre", "modes", "span"]

#: ``mode(field, component, x)``: the mode's values [K, V or m] at points ``x`` (n × 3, m).
Mode = Callable[[str, int | None, npt.NDArray[np.float64]], npt.NDArray[np.float64]]


def modes(fields: tuple[str, ...], dim: int) -> list[Mode]:
    """The kernel modes of a body with ``fields`` in ``dim`` dimensions.

    One constant per scalar field; for the displacement, ``dim`` translations and the
    rotations (1 in 2D, 3 in 3D) about the origin of ``x`` (centre the points first).
    """

    def constant(of: str) -> Mode:
        return lambda f, c, x: np.full(len(x), 1.0 if f == of else 0.0)

    def translation(d: int) -> Mode:
        return lambda f, c, x: np.full(len(x), 1.0 if f == "displacement" and c == d else 0.0)

    def rotation(a: int, b: int) -> Mode:  # in the plane of axes a, b: (−x_b, x_a)
        def mode(f, c, x):
            if f != "displacement":
                return np.zeros(len(x))
            return -x[:, b] if c == a else (x[:, a] if c == b else np.zeros(len(x)))

        return mode

    out = [constant(f) for f in fields if f != "displacement"]
    if "displacement" in fields:
        out += [translation(d) for d in range(dim)]
        planes = [(0, 1)] if dim == 2 else [(0, 1), (1, 2), (0, 2)]
        out += [rotation(a, b) for a, b in planes]
    return out


def centre(points: npt.NDArray[np.float64], comm: MPI.Comm) -> npt.NDArray[np.float64]:
    """The mean of ``points`` (n × d, each rank its own) over every rank [m]."""
    total = comm.allreduce(np.array([*points.sum(axis=0), len(points)]))
    return total[:-1] / max(total[-1], 1.0)


def span(vectors: list[PETSc.Vec], comm: MPI.Comm) -> PETSc.NullSpace:
    """An orthonormal basis of ``vectors`` (modified Gram-Schmidt) as a near-null space.

    A vector that vanishes (a rotation about an axis every row lies on) is left out. The
    vectors are given to the space, which holds them: the caller destroys the space alone.
    """
    basis: list[PETSc.Vec] = []
    for v in vectors:
        for q in basis:
            v.axpy(-v.dot(q), q)
        norm = v.norm()
        if norm > 0:
            v.scale(1.0 / norm)
            basis.append(v)
    space = PETSc.NullSpace().create(vectors=basis, comm=comm)
    for v in vectors:
        v.destroy()
    return space
