"""Nodal errors against independent truth, reduced over all ranks."""

from __future__ import annotations

from collections.abc import Callable, Mapping

import dolfinx
import numpy as np
import numpy.typing as npt
from mpi4py import MPI
from scipy.spatial import cKDTree

__all__ = ["NodalReference", "error_against", "field_values", "relative_nodal_error"]

Values = npt.NDArray[np.float64]


def relative_nodal_error(
    spaces: Mapping[str, dolfinx.fem.FunctionSpace],
    values: Mapping[str, Values],
    reference: Mapping[str, Callable[[Values], Values] | Values],
    comm: MPI.Comm | None = None,
) -> float:
    """Max |u − u_ref| over the owned nodes of every body, divided by the range of u_ref.

    Args:
        spaces: Body name -> P1 space.
        values: Body name -> owned nodal values.
        reference: Body name -> exact function of the node coordinates ``(n, 3)``, or
            owned nodal values of a reference solution.
        comm: Where to reduce (default: every rank, which covers bodies on rank groups;
            a max and a min reduce the same on ranks that each hold a serial copy).
    """
    comm = comm or MPI.COMM_WORLD
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


class NodalReference:
    """A reference solution that any distribution of the same meshes can be compared with.

    Every rank keeps every body's node coordinates and values (gathered once over ``comm``),
    so a scene loaded with another placement, or on other ranks (bodies on other rank
    groups), finds its reference values by coordinates.

    Args:
        spaces: Body name -> P1 space of the reference (the bodies on this rank).
        values: Body name -> owned nodal values of the reference.
        comm: Every rank that holds some body (collective).
    """

    def __init__(
        self,
        spaces: Mapping[str, dolfinx.fem.FunctionSpace],
        values: Mapping[str, Values],
        comm: MPI.Comm = MPI.COMM_WORLD,
    ) -> None:
        owned = {}
        for name, V in spaces.items():
            n = V.dofmap.index_map.size_local
            owned[name] = (V.tabulate_dof_coordinates()[:n], np.asarray(values[name])[:n])
        parts: dict[str, list] = {}
        for held in comm.allgather(owned):  # a serial copy on several ranks: repeated nodes
            for name, pair in held.items():
                parts.setdefault(name, []).append(pair)
        self.nodes, self.trees, self.values = {}, {}, {}
        for name, pairs in parts.items():
            self.nodes[name] = np.concatenate([points for points, _ in pairs])
            self.values[name] = np.concatenate([v for _, v in pairs])
            self.trees[name] = cKDTree(self.nodes[name])

    def save(self, path) -> None:
        """Write the gathered nodes and values (``.npz``) for another run to compare with."""
        arrays = {f"nodes/{name}": points for name, points in self.nodes.items()}
        arrays.update({f"values/{name}": values for name, values in self.values.items()})
        np.savez(path, **arrays)

    @classmethod
    def load(cls, path) -> NodalReference:
        """A reference written by :meth:`save`."""
        reference = cls.__new__(cls)
        reference.nodes, reference.trees, reference.values = {}, {}, {}
        with np.load(path) as arrays:
            for key in arrays.files:
                kind, name = key.split("/", 1)
                getattr(reference, kind)[name] = arrays[key]
        for name, points in reference.nodes.items():
            reference.trees[name] = cKDTree(points)
        return reference

    def at(self, spaces: Mapping[str, dolfinx.fem.FunctionSpace]) -> dict[str, Values]:
        """Reference values at the owned nodes of ``spaces`` (same meshes, any distribution).

        Raises:
            ValueError: A node has no reference node at its place (not the same mesh).
        """
        out = {}
        for name, V in spaces.items():
            points = V.tabulate_dof_coordinates()[: V.dofmap.index_map.size_local]
            distance, index = self.trees[name].query(points)
            extent = float(np.ptp(self.nodes[name], axis=0).max())
            if distance.size and distance.max() > 1e-9 * extent:
                raise ValueError(f"body '{name}': the reference was computed on another mesh")
            out[name] = self.values[name][index]
        return out


def field_values(
    system, field: str = "temperature", component: int | None = None
) -> tuple[dict[str, dolfinx.fem.FunctionSpace], dict[str, Values]]:
    """Spaces and values (copies) of one scalar field (or component) of a system's bodies."""
    spaces, values = {}, {}
    for name, body in system.bodies.items():
        V, parent_of = body.forms.collapsed(field, component)
        spaces[name], values[name] = V, body.U.x.array[parent_of].copy()
    return spaces, values


def error_against(
    system,
    reference: Mapping[str, Callable[[Values], Values] | Values],
    field: str = "temperature",
    component: int | None = None,
) -> float:
    """:func:`relative_nodal_error` of a system's field against a reference (collective)."""
    spaces, values = field_values(system, field, component)
    return relative_nodal_error(spaces, values, reference, comm=system.comm)


def extrapolated_in_conductance(
    solve: Callable[[float], tuple[Mapping[str, dolfinx.fem.FunctionSpace], dict[str, Values]]],
    h: float,
    h1: float,
) -> NodalReference:
    """The solution at a large contact conductance ``h``, extrapolated in 1/h (Richardson).

    ``T(h) = T∞ + a/h + O(1/h²)``: from ``solve(h1)`` and ``solve(2 h1)`` (spaces and values),
    ``T∞ = 2 T₂ − T₁`` and ``a = 2 h₁ (T₁ − T₂)``, with an error of order ``1/h1²``. Where the
    merged matrix's round-off (eps · h) leaves a direct solve at h itself off by more than
    the target, ``h1`` is taken where it does not (1e7 for k/L of order 1 to 100).
    """
    spaces, T1 = solve(h1)
    _, T2 = solve(2 * h1)
    values = {n: 2 * T2[n] - T1[n] + 2 * h1 * (T1[n] - T2[n]) / h for n in T1}
    return NodalReference(spaces, values)
