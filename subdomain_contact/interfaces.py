"""Master layers: the master DOFs of an interface and their maps to both bodies' slave DOFs.

Master vectors are *replicated*: every rank holds the whole vector of an interface, in the
order of the master space's global DOF numbers. Interfaces are much smaller than bodies, so
this costs little and makes every corrector a small dense operation that all ranks repeat
identically; bodies stay distributed.
"""

from __future__ import annotations

from dataclasses import dataclass

import dolfinx
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from subdomain_contact.geometry import Interface, gather_rows, match_points

__all__ = ["MasterLayer", "SlaveMap", "master_layer", "slave_map"]


@dataclass(frozen=True)
class SlaveMap:
    """How one body's slave DOFs on an interface line up with the master DOFs.

    Attributes:
        local_dofs: This rank's owned slave DOFs (local indices in the body space).
        master_index: Master DOF of each of ``local_dofs``.
        gathered_master_index: Master DOF of every slave DOF, in the order of the body's
            global slave numbering (rank by rank), on every rank.
    """

    local_dofs: npt.NDArray[np.int32]
    master_index: npt.NDArray[np.int64]
    gathered_master_index: npt.NDArray[np.int64]

    def scatter(self, master: npt.NDArray[np.float64], body: npt.NDArray[np.float64]) -> None:
        """Write a replicated master vector into this rank's slave entries of ``body``."""
        body[self.local_dofs] = master[self.master_index]

    def gather(self, body: npt.NDArray[np.float64], size: int, comm: MPI.Comm) -> np.ndarray:
        """Replicated master vector from this rank's slave entries of ``body`` (a sum)."""
        master = np.zeros(size)
        master[self.master_index] = body[self.local_dofs]
        return comm.allreduce(master, op=MPI.SUM)


@dataclass(frozen=True)
class MasterLayer:
    """The master DOFs of one interface for one field.

    Attributes:
        interface: The interface.
        V: P1 space on the master mesh (for output and for the monolithic reference).
        size: Number of master DOFs.
        coordinates: Coordinates of every master DOF, by global DOF number, on every rank.
    """

    interface: Interface
    V: dolfinx.fem.FunctionSpace
    size: int
    coordinates: npt.NDArray[np.float64]


def master_layer(interface: Interface) -> MasterLayer:
    """P1 master layer of ``interface``."""
    V = dolfinx.fem.functionspace(interface.master_mesh, ("Lagrange", 1))
    index_map = V.dofmap.index_map
    owned = V.tabulate_dof_coordinates()[: index_map.size_local]
    return MasterLayer(interface, V, index_map.size_global, gather_rows(V.mesh.comm, owned))


def slave_map(
    layer: MasterLayer, V: dolfinx.fem.FunctionSpace, tags: dolfinx.mesh.MeshTags
) -> SlaveMap:
    """Match the slave DOFs of body space ``V`` on the interface to the master DOFs.

    Raises:
        ValueError: The DOFs of the two sides do not coincide (non-conforming interface).
    """
    mesh = V.mesh
    fdim = mesh.topology.dim - 1
    dofs = dolfinx.fem.locate_dofs_topological(V, fdim, tags.find(layer.interface.tag))
    dofs = dofs[dofs < V.dofmap.index_map.size_local]
    coordinates = gather_rows(mesh.comm, V.tabulate_dof_coordinates()[dofs])
    what = f"interface '{layer.interface.name}' (DOFs of body space on {mesh.name})"
    gathered = match_points(layer.coordinates, coordinates, what=what)
    start = mesh.comm.exscan(len(dofs)) or 0
    return SlaveMap(dofs.astype(np.int32), gathered[start : start + len(dofs)], gathered)
