"""VTK output for ParaView: each body's fields and each master layer's channels, with units."""

from __future__ import annotations

from pathlib import Path

import dolfinx
from mpi4py import MPI

from subdomain_contact.system import System

__all__ = ["UNITS", "write_vtk"]

#: Output name of each field, with its unit.
UNITS = {
    "temperature": "temperature [K]",
    "potential": "potential [V]",
    "displacement": "displacement [m]",
}


def write_vtk(directory: str | Path, system: System) -> list[Path]:
    """Write the system's current state for ParaView.

    Files: ``<body>.pvd`` (its scalar fields), ``<body>_displacement.pvd`` (the displacement,
    a vector field of its own) and ``master_<interface>.pvd`` (one scalar per channel).

    Args:
        directory: Output folder (created).
        system: A system at its current state.

    Returns:
        The ``.pvd`` files written (each body by the ranks that solve it).
    """
    directory = Path(directory)
    written = []
    for name, body in system.bodies.items():
        scalars = []
        for field in body.forms.fields:
            V, parent_of = body.forms.collapsed(field)
            f = dolfinx.fem.Function(V, name=UNITS[field])
            f.x.array[:] = body.U.x.array[parent_of]
            if field == "displacement":
                written.append(_write(directory / f"{name}_displacement.pvd", [f]))
            else:
                scalars.append(f)
        if scalars:
            written.append(_write(directory / f"{name}.pvd", scalars))
    for k, layer in system.layers.items():
        start, end = layer.V.dofmap.index_map.local_range
        functions = []
        for c, (field, component) in enumerate(layer.channels):
            label = UNITS[field] if component is None else f"{UNITS[field]} {'xyz'[component]}"
            f = dolfinx.fem.Function(layer.V, name=label)
            values = system.masters[k][c * layer.nodes : (c + 1) * layer.nodes]
            f.x.array[: end - start] = values[start:end]
            f.x.scatter_forward()
            functions.append(f)
        written.append(_write(directory / f"master_{k}.pvd", functions))
    return written


def _write(path: Path, functions: list[dolfinx.fem.Function]) -> Path:
    comm = functions[0].function_space.mesh.comm
    if comm.size == 1 and MPI.COMM_WORLD.size > 1 and MPI.COMM_WORLD.rank != 0:
        return path  # a master layer kept whole on every rank: rank 0 writes it
    if comm.rank == 0:
        path.parent.mkdir(parents=True, exist_ok=True)
    comm.barrier()
    with dolfinx.io.VTKFile(comm, str(path), "w") as vtk:
        vtk.write_function(functions, 0.0)
    return path
