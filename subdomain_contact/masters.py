"""Master layers: each interface's master DOFs, its channels, and their maps to the slave DOFs.

An interface carries one master node per node of its conforming contact surface, and one
*channel* per scalar master field: T, φ, and the displacement components that carry a law (the
normal one alone when the contact slides freely, every one when it is stuck). Master vectors
are channel-major (``c × nodes + node``) and *replicated*: every rank holds the whole vector of
an interface, in the order of the master mesh's global node numbers. Interfaces are much
smaller than bodies, so this costs little and makes every corrector a small dense operation
that all ranks repeat identically; bodies stay distributed.
"""

from __future__ import annotations

from dataclasses import dataclass

import dolfinx
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from subdomain_contact.physics import BodyForms, Problem
from subdomain_contact.scene import Interface, gather_rows, match_points

__all__ = ["Channel", "MasterLayer", "SlaveMap", "channels_of", "contact_dofs", "slave_map"]

Channel = tuple[str, int | None]  # (field, displacement component or None)


@dataclass(frozen=True)
class MasterLayer:
    """The master nodes of one interface and its channels.

    Attributes:
        interface: The interface.
        V: P1 space on the master mesh (for output).
        nodes: Number of master nodes.
        coordinates: Coordinates [m] of every master node, by global number, on every rank.
        channels: The scalar master fields, in master-vector order.
    """

    interface: Interface
    V: dolfinx.fem.FunctionSpace
    nodes: int
    coordinates: npt.NDArray[np.float64]
    channels: tuple[Channel, ...]

    @property
    def size(self) -> int:
        """Master DOFs of the interface: nodes × channels."""
        return self.nodes * len(self.channels)

    def field_index(self) -> npt.NDArray[np.int32]:
        """Channel number of every master DOF."""
        return np.repeat(np.arange(len(self.channels), dtype=np.int32), self.nodes)


def master_layer(problem: Problem, interface: Interface) -> MasterLayer:
    """P1 master layer of ``interface`` with the channels ``problem`` needs there."""
    V = dolfinx.fem.functionspace(interface.master_mesh, ("Lagrange", 1))
    index_map = V.dofmap.index_map
    owned = gather_rows(V.mesh.comm, V.tabulate_dof_coordinates()[: index_map.size_local])
    channels = channels_of(problem, interface.name, owned)
    return MasterLayer(interface, V, index_map.size_global, owned, tuple(channels))


def channels_of(problem: Problem, k: str, coordinates: npt.NDArray[np.float64]) -> list[Channel]:
    """Master channels of interface ``k``: T, φ, and u_n alone (free) or every u_i (stuck).

    Raises:
        ValueError: Free sliding on an interface that is not a plane normal to an axis.
    """
    channels: list[Channel] = []
    for field in problem.fields:
        if field != "displacement":
            channels.append((field, None))
            continue
        body = problem.scene.bodies[problem.scene.interfaces[k].bodies[0]]
        dim = body.mesh.geometry.dim
        if problem.contacts[k].tangential == "stuck":
            channels += [("displacement", c) for c in range(dim)]
            continue
        spread = np.ptp(coordinates[:, :dim], axis=0)
        flat = np.flatnonzero(spread <= 1e-10 * max(spread.max(), 1e-300))
        if len(flat) != 1:
            raise ValueError(
                f"interface '{k}': free sliding needs a flat contact normal to x, y or z "
                f"(coordinate spread {spread}); use tangential='stuck' or split the contact"
            )
        channels.append(("displacement", int(flat[0])))
    return channels


@dataclass(frozen=True)
class SlaveMap:
    """How one body's slave DOFs on an interface line up with the master DOFs.

    Attributes:
        local_dofs: This rank's owned slave DOFs of every channel (local indices in ``W``).
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
        return comm.allreduce(master, op=MPI.SUM) if comm.size > 1 else master


def slave_map(forms: BodyForms, layer: MasterLayer, tags: dolfinx.mesh.MeshTags) -> SlaveMap:
    """Slave DOFs of every channel of one interface, matched to the master nodes.

    Raises:
        ValueError: The DOFs of the two sides do not coincide (non-conforming interface).
    """
    fdim = forms.W.mesh.topology.dim - 1
    comm = forms.W.mesh.comm
    local, index, gathered = [], [], []
    for c, (field, component) in enumerate(layer.channels):
        V, parent_of = forms.collapsed(field, component)
        dofs = dolfinx.fem.locate_dofs_topological(V, fdim, tags.find(layer.interface.tag))
        dofs = dofs[dofs < V.dofmap.index_map.size_local]
        points = gather_rows(comm, V.tabulate_dof_coordinates()[dofs])
        what = f"interface '{layer.interface.name}' ({field} DOFs of '{forms.name}')"
        matched = match_points(layer.coordinates, points, what=what) + c * layer.nodes
        start = comm.exscan(len(dofs)) or 0
        local.append(parent_of[dofs].astype(np.int32))
        index.append(matched[start : start + len(dofs)])
        gathered.append(matched)
    return SlaveMap(np.concatenate(local), np.concatenate(index), np.concatenate(gathered))


def contact_dofs(
    forms: BodyForms, tags: dolfinx.mesh.MeshTags, interfaces: list[str]
) -> npt.NDArray[np.int32]:
    """Owned DOFs of ``W`` (every field and component) on the facets of ``interfaces``.

    These are the DOFs that the half-links touch: a body factorised with them left as a
    dense block takes any change of its contact laws without a new factorisation.
    """
    W = forms.W
    fdim = W.mesh.topology.dim - 1
    facets = np.unique(np.concatenate([tags.find(forms.tags[k]) for k in interfaces] or [[]]))
    blocks = dolfinx.fem.locate_dofs_topological(W, fdim, facets.astype(np.int32))
    bs = W.dofmap.index_map_bs
    dofs = (bs * blocks[:, None] + np.arange(bs)).ravel() if bs > 1 else blocks
    owned = W.dofmap.index_map.size_local * bs
    return np.sort(dofs[dofs < owned]).astype(np.int32)
