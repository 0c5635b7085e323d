"""VTK output for ParaView: one file per body and per master layer, fields named with units."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import dolfinx
import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from subdomain_contact.coupled import CoupledSystem
from subdomain_contact.interfaces import MasterLayer

__all__ = ["UNITS", "write_fields", "write_vtk"]

#: Output name of each field, with its unit.
UNITS = {
    "temperature": "temperature [K]",
    "potential": "potential [V]",
    "displacement": "displacement [m]",
}


def write_vtk(
    directory: str | Path,
    temperatures: Mapping[str, dolfinx.fem.Function],
    layers: Mapping[str, MasterLayer],
    masters: Mapping[str, npt.NDArray[np.float64]],
) -> list[Path]:
    """Write ``<body>.pvd`` per body and ``master_<interface>.pvd`` per master layer.

    Args:
        directory: Output folder (created).
        temperatures: Body name -> temperature Function (named with its unit).
        layers: Interface name -> master layer.
        masters: Interface name -> replicated master values [K].

    Returns:
        The ``.pvd`` files written (each body by the ranks that solve it).
    """
    directory = Path(directory)
    written = []
    for name, T in temperatures.items():
        written.append(_write(directory / f"{name}.pvd", T))
    for k, layer in layers.items():
        T = dolfinx.fem.Function(layer.V, name="temperature [K]")
        start, end = layer.V.dofmap.index_map.local_range
        T.x.array[: end - start] = masters[k][start:end]
        T.x.scatter_forward()
        written.append(_write(directory / f"master_{k}.pvd", T))
    return written


def write_fields(directory: str | Path, system: CoupledSystem) -> list[Path]:
    """Write every body's fields (``<body>.pvd``) and master channels (``master_<k>.pvd``).

    Args:
        directory: Output folder (created).
        system: A coupled system at its current state.

    Returns:
        The ``.pvd`` files written.
    """
    directory = Path(directory)
    written = []
    for name, body in system.bodies.items():
        functions = []
        for field in body.physics.fields:
            V, parent_of = body.physics.collapsed(field)
            f = dolfinx.fem.Function(V, name=UNITS[field])
            f.x.array[:] = body.U.x.array[parent_of]
            functions.append(f)
        written.append(_write(directory / f"{name}.pvd", functions))
    for k, layer in system.layers.items():
        start, end = layer.V.dofmap.index_map.local_range
        functions = []
        for c, (field, component) in enumerate(system.channels[k]):
            label = UNITS[field] if component is None else f"{UNITS[field]} {'xyz'[component]}"
            f = dolfinx.fem.Function(layer.V, name=label)
            values = system.masters[k][c * layer.size : (c + 1) * layer.size]
            f.x.array[: end - start] = values[start:end]
            f.x.scatter_forward()
            functions.append(f)
        written.append(_write(directory / f"master_{k}.pvd", functions))
    return written


def _write(path: Path, function: dolfinx.fem.Function | list[dolfinx.fem.Function]) -> Path:
    functions = function if isinstance(function, list) else [function]
    function = functions[0]
    comm = function.function_space.mesh.comm
    if comm.size == 1 and MPI.COMM_WORLD.size > 1 and MPI.COMM_WORLD.rank != 0:
        return path  # a master layer kept whole on every rank: rank 0 writes it
    if comm.rank == 0:
        path.parent.mkdir(parents=True, exist_ok=True)
    function.function_space.mesh.comm.barrier()
    with dolfinx.io.VTKFile(function.function_space.mesh.comm, str(path), "w") as vtk:
        vtk.write_function(functions, 0.0)
    return path
