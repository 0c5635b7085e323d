"""VTK output for ParaView: each body's fields, each master layer with its contact fields.

One ``scene.pvd`` opens everything at once (one block per file); each body and layer also has
its own ``.pvd``. Vectors are written as vectors (the displacement in a file of its own).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import dolfinx
import numpy as np
from mpi4py import MPI

from subdomain_contact.readback import CONTACT_UNITS, contact_fields
from subdomain_contact.system import System

__all__ = ["UNITS", "plot_vtk", "write_series", "write_vtk"]

#: Output name of each field, with its unit.
UNITS = {
    "temperature": "temperature [K]",
    "potential": "potential [V]",
    "displacement": "displacement [m]",
}


def write_vtk(directory: str | Path, system: System, time: float = 0.0) -> list[Path]:
    """Write the system's current state for ParaView (collective).

    Files: ``<body>.pvd`` (its scalar fields), ``<body>_displacement.pvd`` (the displacement,
    a vector field), ``master_<interface>.pvd`` (one scalar per channel, and the contact
    fields of :func:`~subdomain_contact.readback.contact_fields` with their units), and
    ``scene.pvd``, which lists them all.

    Args:
        directory: Output folder (created).
        system: A system at its current state (a solution, for the contact fields).
        time: The time [s] the files carry.

    Returns:
        The ``.pvd`` files written, ``scene.pvd`` last.
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
                written.append(_write(directory / f"{name}_displacement.pvd", [f], time))
            else:
                scalars.append(f)
        if scalars:
            written.append(_write(directory / f"{name}.pvd", scalars, time))
    # every group's files, known on every rank (a group's root speaks for it)
    mine = written if system.problem.scene.group_comm.rank == 0 else []
    written = [path for part in system.comm.allgather(mine) for path in part]
    fields = contact_fields(system)
    for k, layer in system.layers.items():
        nodal = {
            UNITS[field] if component is None else f"{UNITS[field]} {'xyz'[component]}": (
                system.masters[k][c * layer.nodes : (c + 1) * layer.nodes]
            )
            for c, (field, component) in enumerate(layer.channels)
        }
        for quantity, unit in CONTACT_UNITS.items():
            if quantity in fields[k]:
                nodal[f"{quantity} [{unit}]"] = fields[k][quantity]
        start, end = layer.V.dofmap.index_map.local_range
        functions = []
        for label, values in nodal.items():
            f = dolfinx.fem.Function(layer.V, name=label)
            f.x.array[: end - start] = values[start:end]
            f.x.scatter_forward()
            functions.append(f)
        path = directory / f"master_{k}.pvd"
        # a layer kept whole on every rank (rank groups): rank 0 writes it
        if layer.V.mesh.comm.size == system.comm.size or system.comm.rank == 0:
            _write(path, functions, time)
        system.comm.barrier()
        written.append(path)
    written.append(_scene(directory / "scene.pvd", written, system.comm))
    return written


def write_series(path: str | Path, scenes: list[Path], comm: MPI.Comm) -> Path:
    """One ``.pvd`` of a time series: every dataset of each step's ``scene.pvd``, at its time.

    ParaView opens it as one scene whose time steps are the files' times (rank 0 writes).
    """
    return _scene(Path(path), [Path(s) for s in scenes], comm, parts=False)


def _scene(path: Path, files: list[Path], comm: MPI.Comm, *, parts: bool = True) -> Path:
    """Every dataset of ``files`` at its time in one ``.pvd`` (rank 0).

    ``parts``: one part per file (the files of one time); otherwise each file's own parts
    (files of successive times).
    """
    if comm.rank == 0:
        root = ET.Element("VTKFile", type="Collection", version="0.1")
        collection = ET.SubElement(root, "Collection")
        for part, pvd in enumerate(files):
            for dataset in ET.parse(pvd).getroot().iter("DataSet"):
                ET.SubElement(
                    collection,
                    "DataSet",
                    timestep=dataset.get("timestep", "0"),
                    part=str(part) if parts else dataset.get("part", "0"),
                    name=dataset.get("name", pvd.stem) if not parts else pvd.stem,
                    file=str((pvd.parent / dataset.get("file")).relative_to(path.parent)),
                )
        ET.indent(root)
        ET.ElementTree(root).write(path, xml_declaration=True)
    comm.barrier()
    return path


def _write(path: Path, functions: list[dolfinx.fem.Function], time: float) -> Path:
    """The functions (on one mesh) at ``time`` [s], collective on the mesh's communicator."""
    comm = functions[0].function_space.mesh.comm
    if comm.rank == 0:
        path.parent.mkdir(parents=True, exist_ok=True)
    comm.barrier()
    with dolfinx.io.VTKFile(comm, str(path), "w") as vtk:
        vtk.write_function(functions, time)
    return path


def plot_vtk(
    scene: str | Path,
    png: str | Path,
    *,
    scalars: str = "temperature [K]",
    arrows: str = "displacement [m]",
    title: str = "",
) -> Path:
    """Render a ``scene.pvd`` to PNG with pyvista, as ParaView would show it (serial).

    Every body coloured by ``scalars``, and the ``arrows`` vector field as arrows whose
    largest is 8 % of the scene's size (the scale is printed in the title).

    Returns:
        The PNG written.
    """
    import pyvista

    parts = pyvista.get_reader(str(scene)).read()
    bodies = [b for b in parts if b is not None and b.n_cells and b.get_cell(0).dimension > 0]
    plotter = pyvista.Plotter(off_screen=True, window_size=(1200, 600))
    size = max(np.ptp(np.concatenate([b.points for b in bodies]), axis=0))
    vectors = [b for b in bodies if arrows in b.point_data]
    largest = max((np.abs(b.point_data[arrows]).max() for b in vectors), default=0.0)
    factor = 0.08 * size / largest if largest > 0 else 1.0
    coloured = [b for b in bodies if scalars in b.point_data]
    low = min((b.point_data[scalars].min() for b in coloured), default=0.0)
    high = max((b.point_data[scalars].max() for b in coloured), default=1.0)
    if high - low <= 1e-9 * max(abs(low), abs(high), 1.0):  # uniform: no round-off colours
        low, high = low - 0.5, high + 0.5
    for body in coloured:
        plotter.add_mesh(body, scalars=scalars, clim=(low, high), show_edges=True, cmap="inferno")
    for body in vectors:
        glyphs = body.glyph(orient=arrows, scale=arrows, factor=factor, tolerance=0.02)
        plotter.add_mesh(glyphs, color="cyan")
    if vectors:
        title = f"{title}  arrows: {arrows} scaled by {factor:.3g}".strip()
    plotter.add_title(title, font_size=10)
    if max(np.ptp(b.points[:, 2]) for b in bodies) == 0:
        plotter.view_xy()
        plotter.camera.tight(padding=0.1, adjust_render_window=False)
    else:
        plotter.view_isometric()
    plotter.screenshot(str(png))
    plotter.close()
    return Path(png)
