"""Nodal errors against independent truth, reduced over all ranks."""

from __future__ import annotations

from collections.abc import Callable, Mapping

import dolfinx
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

__all__ = ["relative_nodal_error"]

Values = npt.NDArray[np.float64]


def relative_nodal_error(
    spaces: Mapping[str, dolfinx.fem.FunctionSpace],
    values: Mapping[str, Values],
    reference: Mapping[str, Callable[[Values], Values] | Values],
) -> float:
    """Max |u − u_ref| over the owned nodes of every body, divided by the range of u_ref.

    Args:
        spaces: Body name -> P1 space.
        values: Body name -> owned nodal values.
        reference: Body name -> exact function of the node coordinates ``(n, 3)``, or
            owned nodal values of a reference solution.
    """
    comm = next(iter(spaces.values())).mesh.comm
    worst, low, high = 0.0, np.inf, -np.inf
    for name, V in spaces.items():
        n = V.dofmap.index_map.size_local
        ref = reference[name]
        exact = ref(V.tabulate_dof_coordinates()[:n]) if callable(ref) else np.asarray(ref)[:n]
        if n:
            worst = max(worst, float(np.abs(np.asarray(values[name])[:n] - exact).max()))
            low, high = min(low, float(exact.min())), max(high, float(exact.max()))
    worst = comm.allreduce(worst, op=MPI.MAX)
    spread = comm.allreduce(high, op=MPI.MAX) - comm.allreduce(low, op=MPI.MIN)
    return worst / spread if spread > 0 else worst
