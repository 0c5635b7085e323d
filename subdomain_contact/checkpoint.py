"""Checkpoints of a transient run: the state, the previous times' states and the clock.

Written as NumPy ``.npz`` files, one per body and one for the master layers and the stepper, in
a folder per checkpoint; a checkpoint becomes the latest only once all its files are written
(the folder is renamed into place), and the pointer to it, like the run's history, is rewritten
whole (:func:`write_whole`), so a run killed while writing keeps the one before. Why NumPy
rather than adios4dolfinx: ADIOS2 is not in this project's stack, and the state is all a
restart needs (the mesh comes again from the ``.geo`` file). Each body's values are keyed by
the mesh's *input* node numbers and by component, and the master values by their coordinates,
so a run may resume on another number of ranks or another placement.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import numpy.typing as npt
from mpi4py import MPI

from subdomain_contact.body import Body
from subdomain_contact.scene import match_points
from subdomain_contact.system import System

__all__ = ["latest", "load", "save", "write_whole"]

Vector = npt.NDArray[np.float64]

#: Checkpoints kept (the latest ones): one more than the latest, should a disk fill up.
KEEP = 2


def write_whole(path: str | Path, text: str) -> None:
    """Replace a file's text at once: a run killed while writing leaves the old file whole.

    The text goes to ``<name>.part`` first, which :func:`os.replace` then renames over the
    file (atomic on POSIX file systems); :meth:`Path.write_text` truncates the file first, and
    a SIGKILL between the truncation and the write left it empty.
    """
    path = Path(path)
    part = path.with_name(path.name + ".part")
    part.write_text(text)
    os.replace(part, path)


def save(
    directory: str | Path,
    system: System,
    clock: dict,
    arrays: dict[str, list[dict]],
    master_arrays: dict[str, list[dict]] | None = None,
) -> Path:
    """Write a checkpoint of the system's state (collective); returns its folder.

    Args:
        directory: The run's checkpoint folder; the checkpoint goes to ``step_<n>`` in it.
        system: The system.
        clock: JSON-ready numbers of the stepper (``steps`` names the folder).
        arrays: Extra per-body arrays shaped like a body's state (the stepper's past states),
            by name: a list of ``{body: array}``.
        master_arrays: Extra arrays shaped like the masters (their past values), by name: a
            list of ``{interface: array}``.
    """
    directory = Path(directory)
    final = directory / f"step_{clock['steps']:06d}"
    partial = directory / f".partial_{clock['steps']:06d}"
    comm = system.comm
    if comm.rank == 0:
        shutil.rmtree(partial, ignore_errors=True)
        partial.mkdir(parents=True)
    comm.barrier()
    for name, body in system.bodies.items():
        keys = _keys(body)[: body.size]
        values = {
            "state": body.U.x.array[: body.size],
            "previous": body.forms.history[0].x.array[: body.size],
            "before_previous": body.forms.history[1].x.array[: body.size],
        }
        for label, past in arrays.items():
            for i, states in enumerate(past):
                values[f"{label}_{i}"] = states[name][: body.size]
        gathered = body.comm.gather((keys, values), root=0)
        if body.comm.rank == 0:
            all_keys = np.concatenate([k for k, _ in gathered])
            order = np.argsort(all_keys)
            columns = {
                label: np.concatenate([v[label] for _, v in gathered])[order] for label in values
            }
            np.savez(partial / f"body_{name}.npz", keys=all_keys[order], **columns)
    comm.barrier()  # every group's root has written its bodies
    if comm.rank == 0:
        masters = {f"{k}_values": v for k, v in system.masters.items()}
        for label, past in (master_arrays or {}).items():
            for i, values in enumerate(past):
                masters |= {f"{label}.{i}.{k}": v for k, v in values.items()}
        points = {f"{k}_points": layer.coordinates for k, layer in system.layers.items()}
        np.savez(partial / "masters.npz", **masters, **points)
        (partial / "clock.json").write_text(json.dumps(clock))
        shutil.rmtree(final, ignore_errors=True)
        partial.rename(final)
        write_whole(directory / "latest", final.name)
        for older in sorted(directory.glob("step_*"))[:-KEEP]:
            shutil.rmtree(older)
    comm.barrier()
    return final


def latest(directory: str | Path, comm: MPI.Comm) -> Path | None:
    """The latest complete checkpoint in ``directory`` (None if there is none)."""
    pointer = Path(directory) / "latest"
    name = pointer.read_text().strip() if comm.rank == 0 and pointer.exists() else None
    name = comm.bcast(name, root=0)
    return None if name is None else Path(directory) / name


def load(folder: str | Path, system: System) -> tuple[dict, dict, dict]:
    """Put a checkpoint's state into the system (collective).

    Args:
        folder: A checkpoint's folder (:func:`latest`).
        system: A system of the same scene and problem (any number of ranks, any placement).

    Returns:
        The clock; the extra arrays as ``{label: [{body: array}]}`` (each body's local
        entries, ghosts included), as many of each label as were saved; the extra master
        arrays as ``{label: [{interface: array}]}``.

    Raises:
        ValueError: A checkpoint of another scene (its nodes or fields are not this one's).
    """
    folder = Path(folder)
    clock = json.loads((folder / "clock.json").read_text())
    extra: dict[str, list[dict]] = {}
    failure = None
    for name, body in system.bodies.items():
        with np.load(folder / f"body_{name}.npz") as data:
            stored = data["keys"]
            keys = _keys(body)
            where = np.searchsorted(stored, keys)
            where[where == len(stored)] = 0
            if len(stored) == 0 or np.any(stored[where] != keys):
                failure = f"{folder}: body '{name}' has nodes or fields this checkpoint lacks"
                break
            body.U.x.array[:] = data["state"][where]
            body.forms.history[0].x.array[:] = data["previous"][where]
            body.forms.history[1].x.array[:] = data["before_previous"][where]
            for key in data.files:  # the extras: "<label>_<i>"
                label, _, i = key.rpartition("_")
                if label and i.isdigit():
                    past = extra.setdefault(label, [])
                    past.extend({} for _ in range(int(i) + 1 - len(past)))
                    past[int(i)][name] = data[key][where]
    messages = [m for m in system.comm.allgather(failure) if m]
    if messages:
        raise ValueError(f"{messages[0]}: restart from a checkpoint of the same scene")
    master_extra: dict[str, list[dict]] = {}
    with np.load(folder / "masters.npz") as data:
        indices = {}
        for k, layer in system.layers.items():
            what = f"{folder}: interface '{k}'"
            indices[k] = match_points(data[f"{k}_points"], layer.coordinates, what=what)

        def read(key: str, k: str) -> npt.NDArray[np.float64]:
            return data[key].reshape(-1, len(indices[k]))[:, indices[k]].ravel()

        masters = {k: read(f"{k}_values", k) for k in indices}
        for key in data.files:  # the extras: "<label>.<i>.<interface>"
            parts = key.split(".", 2)
            if len(parts) == 3 and parts[1].isdigit() and parts[2] in indices:
                past = master_extra.setdefault(parts[0], [])
                past.extend({} for _ in range(int(parts[1]) + 1 - len(past)))
                past[int(parts[1])][parts[2]] = read(key, parts[2])
    system.set_masters(masters)
    return clock, extra, master_extra


def _keys(body: Body) -> npt.NDArray[np.int64]:
    """A partition-independent key of every local entry of the body's state (ghosts too).

    ``file node number × components + component``, components over the body's fields in
    order (a displacement has one per axis); degree-1 Lagrange spaces put one DOF of each
    component on each node of a degree-1 mesh, in the order of the cell's geometry nodes.
    """
    forms, mesh = body.forms, body.forms.W.mesh
    nodes = body.scene_body.node_numbers()
    geometry = mesh.geometry.dofmaps[0]
    channels = [
        (field, component)
        for field in forms.fields
        for component in ((None,) if field != "displacement" else range(mesh.geometry.dim))
    ]
    keys = np.full(len(body.U.x.array), -1, dtype=np.int64)
    for c, (field, component) in enumerate(channels):
        V, parent_of = forms.collapsed(field, component)
        node_of = np.empty(len(parent_of), dtype=np.int64)
        node_of[V.dofmap.list.ravel()] = nodes[geometry.ravel()]
        keys[parent_of] = node_of * len(channels) + c
    return keys
