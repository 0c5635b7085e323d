"""Scenes from gmsh ``.geo`` files: one dolfinx mesh per body, one master mesh per contact.

A scene is read from the *named* physical groups of a ``.geo`` file: cell groups are bodies,
facet groups are contact interfaces (when they lie between two bodies) or boundaries (by name,
for boundary conditions). Rank 0 meshes the file with gmsh, ``dolfinx.io.gmsh.model_to_mesh``
distributes the parent mesh, and every body becomes its own submesh. Each interface gets a
master mesh: a conforming copy of its facets, checked node by node against both bodies' sides.
"""

from __future__ import annotations

import hashlib
import os
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from collections.abc import Set as AbstractSet
from dataclasses import dataclass
from pathlib import Path

import dolfinx
import dolfinx.graph
import dolfinx.io
import gmsh
import numpy as np
import numpy.typing as npt
from mpi4py import MPI
from scipy.spatial import cKDTree

from subdomain_contact.schur import factorisation_work

#: Unknowns per node that the placement of bodies on ranks counts with (T and φ): the
#: scene is placed before the problem names its fields.
PLACEMENT_FIELDS = 2

__all__ = ["Body", "Interface", "Scene", "gather_rows", "load_scene", "match_points"]

#: A rank whose load (its bodies' cells, each over the ranks of its group) exceeds the mean
#: load of the ranks by more than this factor, with a body on it that may be solved iteratively,
#: makes a scene placed ``"auto"`` spread every body over all ranks instead. A body
#: solved by Krylov + AMG spreads well, and alone on its ranks it leaves the others waiting
#: in its collective calls (``gdb``: the collector bar slot at 1.07M DOFs, 2 ranks, the
#: block of 794k DOFs on one, the bar and cast iron on the other). The factor is the inverse
#: of a spread solve's parallel efficiency on 2 ranks, 0.78–0.82 (the slot at 204k DOFs: 2
#: ranks took 0.61–0.64 of one rank's time). Measured, the slot at 34,510 DOFs nested from
#: 9,075 (2 ranks, one BLAS thread, the block made iterative by option, 2026-11-28; the block
#: 73 % of the cells, 1.45 times the mean): bodies on rank groups 94.8 s on the fine level,
#: spread 70.9 s, the same 10 Newton steps. Where every body is factorised the groups win
#: (the same mesh, 77.7 s against 85.6 s), so factorised bodies alone never spread.
SPREAD_LOAD = 1.25

#: A body meshed in 3D whose problem has not both T or φ and u is solved by Krylov + AMG by
#: default (``solver="auto"``) where its largest front (:func:`largest_front`) holds more
#: DOFs than this (:data:`SWEEP_ABOVE` for one that has). A sparse factorisation
#: stores about front² and works about front³ (nested dissection), so it outgrows a chunky
#: body, not a slender one: a cube of 100k DOFs of T, φ and u has a front of 7.8k, the
#: collector bar slot's bar at 1M DOFs (0.16 × 0.08 m across, 2.2 m long) 1,090. A cube of
#: one field passes it at about 125k DOFs.
FRONT_ABOVE = 5_000

#: A 3D body of T or φ and of u is solved by the factorised sweep (FGMRES on one sweep over
#: its (T, φ) block, then its u block, each factorised in single precision with block
#: low-rank factors: ``body.FACTORISED_SWEEP``) by default where its largest front F cubed
#: over its DOFs n passes this (:func:`sweep_weight`): the whole factorisation works about
#: F³ (its top separator's dense front), the sweep saves most of it (its splits' fronts are
#: 2/5 and 3/5 of F, factorised in single precision) and pays FGMRES iterations of about n
#: each. Measured (2 ranks, one run each, the sweep against the whole factorisation with its
#: Schur block; F³/n, factorised time over swept time), the row of four 3D blocks: 6,660
#: (5,975 DOFs) 0.68, 11,070 (14,845) 0.98, 21,800 (31,420) 1.20, 41,900 (74,580) 1.60,
#: 140,800 (218,790) 1.91; the collector bar slot's block at 34,510 DOFs, 11,000: 1.41 (on
#: the level), at 174,240, 61,600: 1.70; its slender bar at 1.07M DOFs, 8,640: 0.80 (two
#: Newton steps, 668 s against 838 s), on the row's curve where its front alone (1,090, the
#: row's 920 won 1.6 times) was not. The row's crossover is about 11,500 (2026-12-07/08).
SWEEP_ABOVE = 12_000

#: The share of a body's vertices on its contacts above which it is not swept by default.
#: The sweep leaves out only the contacts' dependence on u; where nearly every node is on a
#: contact, that is most of the body's coupling. The collector bar slot's cast iron (a shell
#: 15-25 mm thick between the bar and the block: 95 % of its vertices on contacts at 34,510
#: DOFs) swept by option (2 ranks, 2026-12-07): its FGMRES stopped at 1,000 iterations
#: (PETSc reason -3), in double precision, at each of the level's last 8 Jacobians and MUMPS
#: took it each time, 101.4 s against 42.8 s for the level; the bar (38 %) and the block
#: (12.5 %) never fell short.
SWEEP_CONTACT_SHARE = 0.5


def largest_front(mesh: dolfinx.mesh.Mesh, per_node: int) -> int:
    """DOFs near the cut across a body's longest side at its middle: about its largest front.

    The nodes within half a mean cell diameter of the plane that halves the longest side
    of the body's bounding box (about two layers of nodes), times the DOFs per node. The
    first cut of a nested-dissection ordering, the costliest front of the factorisation.
    """
    comm, tdim = mesh.comm, mesh.topology.dim
    owned = mesh.geometry.index_map().size_local
    x = mesh.geometry.x[:owned]
    lo, hi = np.empty(3), np.empty(3)
    comm.Allreduce(x.min(axis=0) if owned else np.full(3, np.inf), lo, op=MPI.MIN)
    comm.Allreduce(x.max(axis=0) if owned else np.full(3, -np.inf), hi, op=MPI.MAX)
    side = int(np.argmax(hi - lo))
    cells = mesh.topology.index_map(tdim).size_local
    diameters = comm.allreduce(mesh.h(tdim, np.arange(cells, dtype=np.int32)).sum())
    h = diameters / comm.allreduce(cells)
    near = np.abs(x[:, side] - 0.5 * (lo[side] + hi[side])) < 0.5 * h
    return per_node * comm.allreduce(int(np.count_nonzero(near)))


def sweep_weight(front: int, dofs: int) -> float:
    """``front³ / dofs``: a whole factorisation's work over one Krylov iteration's.

    Of a body's largest front and its DOFs (:data:`SWEEP_ABOVE`).
    """
    return front**3 / max(dofs, 1)


def contact_share(
    mesh: dolfinx.mesh.Mesh, facet_tags: dolfinx.mesh.MeshTags, tags: Sequence[int]
) -> float:
    """The share of the mesh's vertices that lie on facets of ``tags`` (its contacts)."""
    fdim = mesh.topology.dim - 1
    mesh.topology.create_connectivity(fdim, 0)
    facets = facet_tags.indices[np.isin(facet_tags.values, tags)]
    vertices = dolfinx.mesh.compute_incident_entities(mesh.topology, facets, fdim, 0)
    owned = mesh.topology.index_map(0).size_local
    on = np.count_nonzero(np.unique(vertices) < owned)
    return mesh.comm.allreduce(on) / max(mesh.comm.allreduce(owned), 1)


@dataclass(frozen=True)
class Body:
    """One body (natural subdomain) with its own mesh.

    Attributes:
        name: Name of the body's physical group.
        mesh: The body's mesh (a submesh of the scene's parent mesh).
        facet_tags: Facet tags of the body mesh, with the parent's physical-group tags.
        boundaries: Facet group name -> tag, for the groups that have facets on this body.
        file_nodes: The mesh file's number of each local geometry node, where it is not the
            mesh's own ``input_global_indices`` (a body spread again over a rank group).
    """

    name: str
    mesh: dolfinx.mesh.Mesh
    facet_tags: dolfinx.mesh.MeshTags
    boundaries: Mapping[str, int]
    file_nodes: npt.NDArray[np.int64] | None = None

    def node_numbers(self) -> npt.NDArray[np.int64]:
        """The mesh file's number of each local geometry node: the same on any partition."""
        if self.file_nodes is not None:
            return self.file_nodes
        return self.mesh.geometry.input_global_indices.astype(np.int64)


@dataclass(frozen=True)
class Interface:
    """A contact interface between two bodies and its master mesh.

    Attributes:
        name: Name of the interface's physical group.
        bodies: The two bodies it joins, in the order the scene lists them.
        tag: Its facet tag on both bodies' meshes.
        master_mesh: The master layer's mesh, of codimension 1, conforming with both sides.
    """

    name: str
    bodies: tuple[str, str]
    tag: int
    master_mesh: dolfinx.mesh.Mesh


@dataclass(frozen=True)
class Placement:
    """Where a scene's bodies are solved.

    Attributes:
        owner: Body name -> index of the rank group that solves it.
        group: This rank's group index.
        group_comm: Communicator of this rank's group.
        group_roots: Rank (in the scene's communicator) of each group's first rank.
    """

    owner: Mapping[str, int]
    group: int
    group_comm: MPI.Comm
    group_roots: tuple[int, ...]


class Scene:
    """Bodies and contact interfaces read from one ``.geo`` file.

    A scene on rank groups is placed when it is first asked where a body is solved: by the
    first :class:`~subdomain_contact.system.System` built on it, which knows how each body is
    solved (:meth:`place`), or else by its bodies' sizes; placing is collective on
    :attr:`comm`, so every rank asks (every rank builds the ``System``).

    Attributes:
        source: The ``.geo`` file.
        comm: Communicator of the whole scene.
        bodies: Every body; those of other rank groups (every body until the scene is
            placed) as serial copies (names, boundaries).
        interfaces: Every interface.
    """

    def __init__(
        self,
        source: Path,
        comm: MPI.Comm,
        bodies: Mapping[str, Body],
        interfaces: Mapping[str, Interface],
        placement: Placement | None,
        *,
        spread: bool = False,
        like: Scene | None = None,
    ) -> None:
        """A scene; ``placement`` None: placed on rank groups later (:meth:`place`).

        ``like``: a scene whose groups it takes; ``spread``: :func:`_place` may spread.
        """
        self.source, self.comm = source, comm
        self.bodies, self.interfaces = bodies, interfaces
        self._placement, self._spread, self._like = placement, spread, like

    @property
    def placed(self) -> bool:
        """Whether the bodies have their rank groups."""
        return self._placement is not None

    def place(self, solver_of: Callable[[Body], str] | None = None) -> None:
        """Place the bodies on rank groups and distribute each over its group; once, collective.

        ``solver_of``: a body's solver (:data:`~subdomain_contact.body.SOLVERS`), which
        :func:`_place` balances kind by kind; None: by the bodies' sizes alone. A scene
        loaded like another takes its groups, that scene placed first by its own bodies'
        solvers (the finer mesh of a nested iteration). A placed scene is left as it is.
        """
        if self._placement is not None:
            return
        if self._like is not None:
            self._like.place(solver_of)
            self._put(self._like.owner, self.comm.allgather(self._like.group))
            return
        solvers = None
        if solver_of is not None:
            solvers = {name: solver_of(body) for name, body in self.bodies.items()}
        cells = {
            n: b.mesh.topology.index_map(b.mesh.topology.dim).size_global
            for n, b in self.bodies.items()
        }
        if solvers is None:  # a body that some problem (T, φ and u: dim + 2 a node) iterates
            most = self.dim + 2
            iterative = {
                n for n, b in self.bodies.items() if self.solver_by_size(b, most, True) != "direct"
            }
        else:
            iterative = {n for n, s in solvers.items() if s != "direct"}
        work = None if iterative else _work(self)  # an iterative body is not condensed
        self._put(
            *_place(cells, work, self.comm.size, iterative if self._spread else set(), solvers)
        )

    def _put(self, owner: Mapping[str, int], group_of_rank: Sequence[int]) -> None:
        """Distribute each body over its group's ranks (body -> group, rank -> group)."""
        self._like = None
        group = group_of_rank[self.comm.rank]
        group_comm = self.comm.Split(group, self.comm.rank)
        roots = tuple(group_of_rank.index(g) for g in range(max(group_of_rank) + 1))
        self.bodies = {
            name: _distribute(body, group_comm) if owner[name] == group else body
            for name, body in self.bodies.items()
        }
        self._placement = Placement(dict(owner), group, group_comm, roots)

    @property
    def owner(self) -> Mapping[str, int]:
        """Body name -> index of the rank group that solves it."""
        self.place()
        return self._placement.owner

    @property
    def group(self) -> int:
        """This rank's group index."""
        self.place()
        return self._placement.group

    @property
    def group_comm(self) -> MPI.Comm:
        """Communicator of this rank's group."""
        self.place()
        return self._placement.group_comm

    @property
    def group_roots(self) -> tuple[int, ...]:
        """Rank (in :attr:`comm`) of each group's first rank."""
        self.place()
        return self._placement.group_roots

    @property
    def dim(self) -> int:
        """Topological dimension of the bodies' meshes (2 or 3)."""
        return next(iter(self.bodies.values())).mesh.topology.dim

    def contact_share(self, body: Body) -> float:
        """The share of ``body``'s mesh vertices on its contact interfaces (collective)."""
        tags = [i.tag for i in self.interfaces_of(body.name)]
        return contact_share(body.mesh, body.facet_tags, tags)

    def solver_by_size(self, body: Body, per_node: int, sweeps: bool) -> str:
        """How ``body`` is solved by default (its solver "auto"): a ``System`` solver.

        Meshed in 3D, with its largest front (:func:`largest_front`, ``per_node`` DOFs a
        node) cubed over its DOFs above :data:`SWEEP_ABOVE` (:func:`sweep_weight`), where its
        problem ``sweeps`` (has T or φ and u: :func:`~subdomain_contact.solvers.sweepable`)
        and at most :data:`SWEEP_CONTACT_SHARE` of its vertices are on contacts
        (:meth:`contact_share`, counted only then): ``"split"``; any other whose front is
        above :data:`FRONT_ABOVE`: ``"iterative"``; else ``"direct"``. Collective.
        """
        mesh = body.mesh
        if mesh.topology.dim != 3:
            return "direct"
        front = largest_front(mesh, per_node)
        dofs = mesh.topology.index_map(0).size_global * per_node
        heavy = sweep_weight(front, dofs) > SWEEP_ABOVE
        if sweeps and heavy and self.contact_share(body) <= SWEEP_CONTACT_SHARE:
            return "split"
        return "iterative" if front > FRONT_ABOVE else "direct"

    def interfaces_of(self, body: str) -> list[Interface]:
        """Interfaces that ``body`` touches, in scene order."""
        return [i for i in self.interfaces.values() if body in i.bodies]

    def is_local(self, body: str) -> bool:
        """Whether this rank's group solves ``body``."""
        return self.owner[body] == self.group

    def check_entries(
        self, materials: Mapping[str, object], contacts: Mapping[str, object]
    ) -> None:
        """Require one material per body and one contact per interface, by name.

        Raises:
            ValueError: An entry is missing or names nothing in the scene.
        """
        for kind, given, known in [
            ("body", materials, self.bodies),
            ("interface", contacts, self.interfaces),
        ]:
            if set(given) != set(known):
                raise ValueError(
                    f"{self.source}: give one {kind} entry for each of {sorted(known)}, "
                    f"got {sorted(given)}"
                )

    def unanchored(self, joining: Iterable[str], anchors: set[str]) -> list[str] | None:
        """The first set of bodies (sorted names) that no anchor holds, or None.

        Bodies join through the interfaces ``joining``; a set is held where one of its
        bodies has a boundary group in ``anchors``.
        """
        group = {name: {name} for name in self.bodies}
        for k in joining:
            first, second = self.interfaces[k].bodies
            merged = group[first] | group[second]
            for name in merged:
                group[name] = merged
        for members in {frozenset(g) for g in group.values()}:
            if not any(anchors & set(self.bodies[n].boundaries) for n in members):
                return sorted(members)
        return None

    @property
    def shared(self) -> bool:
        """Whether every body is spread over all ranks (one group)."""
        return len(self.group_roots) == 1


def load_scene(
    path: str | Path,
    *,
    bodies: Sequence[str],
    interfaces: Sequence[str],
    parameters: Mapping[str, float] | None = None,
    comm: MPI.Comm = MPI.COMM_WORLD,
    placement: str | Scene = "auto",
    mesh_cache: str | Path | None = None,
    refinements: int = 0,
) -> Scene:
    """Mesh a ``.geo`` file and split it into bodies and master layers.

    Args:
        path: The ``.geo`` file.
        bodies: Names of the cell physical groups that are bodies.
        interfaces: Names of the facet physical groups that are contact interfaces.
        parameters: Values for the file's ``DefineConstant`` names (as ``gmsh -setnumber``).
        comm: Communicator of the scene.
        placement: ``"shared"``: every body spread over all ranks of ``comm``.
            ``"groups"``: ranks split into groups, each body solved by one group (one body
            per group when there are enough ranks, in proportion to their cells; several
            bodies per rank otherwise, each kind of body solver shared out among the ranks).
            Every rank meshes the file and keeps the master layers; a group distributes only
            its own bodies, when the groups are chosen: by the first ``System`` built on the
            scene, which knows each body's solver (:meth:`Scene.place`), or when the scene is
            first asked where a body is solved. ``"auto"`` (default): ``"groups"`` with
            several bodies on several ranks, else ``"shared"``; with every body spread over
            all ranks (one group) where a body solved iteratively (or, placed before a
            ``System``, one that may be: :meth:`solver_by_size` with T, φ and u) would
            leave a rank more than :data:`SPREAD_LOAD` times the mean load. A scene
            of the same bodies (on ``comm``): its rank groups, so that a state interpolates
            between the two (a coarser mesh of a nested iteration, ``System.interpolate``);
            where that scene is not placed yet, both are placed when the first ``System``
            on either is built, by the solvers of that scene's bodies.
        mesh_cache: A directory where the mesh gmsh makes is kept as a ``.msh`` file, named
            by a hash of the ``.geo`` text, the parameters and gmsh's version, and read
            back instead of meshing again (two 3D blocks at 939,678 DOFs: a load took
            530 s meshing, 181 s reading back, both beside a test run). Files the ``.geo``
            includes are not in the hash: delete the directory to mesh again.
        refinements: Uniform refinements of gmsh's mesh (gmsh's ``refine``: each
            tetrahedron split into 8, each triangle into 4, the contacts alike on both
            sides): nested meshes of one geometry whose element sizes halve, the meshes of a
            mesh study. Flat faces only: a new node stays on its parent's edge.

    Raises:
        ValueError: Unknown parameter, missing or overlapping group, empty or
            non-conforming interface, bodies that touch with no interface listed between
            them, or a file gmsh cannot mesh; the message names the file and the group.
    """
    path = Path(path)
    like = placement if isinstance(placement, Scene) else None
    auto = placement == "auto"
    if like is not None:
        if set(like.bodies) != set(bodies):
            raise ValueError(
                f"{path}: placed like a scene of other bodies ({sorted(like.bodies)}, "
                f"not {sorted(bodies)})"
            )
        placement = "shared" if like.placed and like.shared else "groups"
    elif placement == "auto":
        placement = "groups" if len(bodies) > 1 else "shared"
    if placement == "groups" and comm.size > 1:
        return _grouped(
            load_scene(
                path,
                bodies=bodies,
                interfaces=interfaces,
                parameters=parameters,
                comm=MPI.COMM_SELF,
                mesh_cache=mesh_cache,
                refinements=refinements,
            ),
            comm,
            like,
            spread=auto,
        )
    if placement not in ("shared", "groups"):
        raise ValueError(f"placement = {placement!r}: use 'auto', 'shared' or 'groups'")
    cache = Path(mesh_cache) if mesh_cache is not None else None
    if refinements < 0:
        raise ValueError(f"{path}: refinements = {refinements}, not a count (0, 1, 2, ...)")
    data = _mesh_geo(path, dict(parameters or {}), comm, cache, refinements)
    parent, groups = data.mesh, data.physical_groups
    tdim = parent.topology.dim
    for name in (*bodies, *interfaces):
        if name not in groups:
            raise ValueError(
                f"{path}: no physical group named '{name}'; the file defines {sorted(groups)}"
            )
    for name, dim in [(b, tdim) for b in bodies] + [(i, tdim - 1) for i in interfaces]:
        if groups[name].dim != dim:
            raise ValueError(
                f"{path}: physical group '{name}' has dimension {groups[name].dim}, expected {dim}"
            )
    facet_groups = {n: g.tag for n, g in groups.items() if g.dim == tdim - 1}
    body_of_cell = _body_of_cell(data.cell_tags, {b: groups[b].tag for b in bodies}, parent)
    scene_bodies = {
        name: _make_body(parent, data, name, groups[name].tag, facet_groups) for name in bodies
    }
    scene_interfaces = {}
    for name in interfaces:
        scene_interfaces[name] = _make_interface(
            path, parent, data.facet_tags, name, groups[name].tag, list(bodies), body_of_cell
        )
        _check_conforming(path, scene_interfaces[name], scene_bodies)
    _check_touching(
        path, parent, data.facet_tags, [groups[i].tag for i in interfaces], list(bodies),
        body_of_cell,
    )  # fmt: skip
    owner = dict.fromkeys(scene_bodies, 0)
    return Scene(path, comm, scene_bodies, scene_interfaces, Placement(owner, 0, comm, (0,)))


def _grouped(
    serial: Scene, comm: MPI.Comm, like: Scene | None = None, *, spread: bool = False
) -> Scene:
    """The bodies of a serial scene (on every rank), placed later by :meth:`Scene.place`.

    ``like``: its rank groups (now if it is placed); else :func:`_place`'s (``spread``: one
    group of every rank where it finds that that balances better).
    """
    scene = Scene(
        serial.source, comm, serial.bodies, serial.interfaces, None, spread=spread, like=like
    )
    if like is not None and like.placed:
        scene.place()
    return scene


def _work(scene: Scene) -> dict[str, float] | None:
    """Each body's factorisation work [flops], estimated from its nodes and contact nodes.

    The fields are not known yet: counted for :data:`PLACEMENT_FIELDS` unknowns per node.
    None where some body would not be condensed: the sparse strip corrector then serves its
    interfaces, and its factorisation over the ranks of those bodies follows their cells.
    """
    work = {}
    for name, body in scene.bodies.items():
        nodes = [i.master_mesh.topology.index_map(0).size_global
                 for i in scene.interfaces.values() if name in i.bodies]  # fmt: skip
        contact = PLACEMENT_FIELDS * sum(nodes)
        size = PLACEMENT_FIELDS * body.mesh.topology.index_map(0).size_global
        estimate = factorisation_work(size, contact, body.mesh.topology.dim)
        if estimate is None:
            return None
        work[name] = estimate
    return work


def _place(
    cells: dict[str, int],
    work: dict[str, float] | None,
    ranks: int,
    iterative: AbstractSet[str] = frozenset(),
    solvers: Mapping[str, str] | None = None,
) -> tuple[dict[str, int], list[int]]:
    """Body -> group, and rank -> group; one group of every rank where that balances better.

    Where a rank holding a body of ``iterative`` carries more than :data:`SPREAD_LOAD` times
    the mean load, every body is spread over all ranks (one group).

    With a rank or more per body, groups sized by cells (a body spread over several ranks is
    factorised whole, a cost that follows its cells). With fewer ranks, bodies packed on
    ranks, largest first, by their factorisation ``work`` where every body is condensed on
    its contact DOFs, else by cells. Measured, 2 ranks, 12 time steps of the 2D preheat: by
    cells its three bodies with the largest condensations shared a rank, 11.9 s (one rank:
    12.6 s); by work 9.4 s. Where some bodies are not condensed, the work of their strip
    corrector is not in the estimate: 8 steps of the preheat's small 3D quarter took 13.1 s
    packed by the estimate and 11.1 s by cells.

    Bodies of several ``solvers`` (body -> :data:`~subdomain_contact.body.SOLVERS`): each,
    largest first, onto the rank whose largest share of a kind's load is the least with the
    body on it (then the least load; one kind: as above), so that a Jacobian's
    factorisations and the interface solves' Krylov body solves each keep every rank at
    work where the kinds weigh alike, and a light kind does not join the heaviest rank.
    Measured, the row of four 3D blocks at 1.01M DOFs, 2 ranks, the held end blocks by the
    sweep and the floating inner two by AMG (py-spy: each rank waited for the other 27 % of
    the time, in turn): the two AMG blocks on one rank 1,973.8 s and 8.76 GiB, one block of
    each kind a rank 1,760.6 s and 6.46 GiB.
    """
    if ranks >= len(cells):
        names = sorted(cells, key=lambda n: -cells[n])
        share = dict.fromkeys(names, 1)
        for _ in range(ranks - len(names)):
            share[max(names, key=lambda n: cells[n] / share[n])] += 1
        order = list(cells)  # groups in scene order, consecutive ranks
        owner = {n: g for g, n in enumerate(order)}
        group_of_rank = [owner[n] for n in order for _ in range(share[n])]
        load = [cells[order[g]] / share[order[g]] for g in group_of_rank]
        total = sum(cells.values())
    else:
        weight = cells if work is None else work
        kind = dict.fromkeys(weight, "") | dict(solvers or {})
        heft = {k: sum(w for n, w in weight.items() if kind[n] == k) for k in kind.values()}
        load, shares = [0.0] * ranks, [dict.fromkeys(heft, 0.0) for _ in range(ranks)]
        owner = {}

        def fullest(rank: int, name: str) -> float:
            """The rank's largest share of a kind with the body on it (12 digits: ties)."""
            share = dict(shares[rank])
            share[kind[name]] += weight[name] / heft[kind[name]]
            return round(max(share.values()), 12)

        for name in sorted(weight, key=lambda n: -weight[n]):
            owner[name] = min(range(ranks), key=lambda r: (fullest(r, name), load[r]))
            load[owner[name]] += weight[name]
            shares[owner[name]][kind[name]] += weight[name] / heft[kind[name]]
        group_of_rank, total = list(range(ranks)), sum(weight.values())
    holding = {owner[n] for n in iterative}  # groups with a body that may be iterative
    waiting = [load[r] for r, g in enumerate(group_of_rank) if g in holding]
    if max(waiting, default=0.0) > SPREAD_LOAD * total / ranks:
        return dict.fromkeys(cells, 0), [0] * ranks
    return owner, group_of_rank


def _distribute(body: Body, comm: MPI.Comm) -> Body:
    """Spread a serial body mesh (the same on every rank) over ``comm``, facet tags too."""
    mesh, root = body.mesh, comm.rank == 0
    gdim, fdim = mesh.geometry.dim, mesh.topology.dim - 1
    cells = mesh.geometry.dofmaps[0].astype(np.int64)
    x = mesh.geometry.x[:, :gdim]
    new = dolfinx.mesh.create_mesh(
        comm, cells if root else cells[:0], mesh.ufl_domain(), x if root else x[:0]
    )
    tags = body.facet_tags
    mesh.topology.create_connectivity(fdim, mesh.topology.dim)
    entities = dolfinx.mesh.entities_to_geometry(mesh, fdim, tags.indices).astype(np.int64)
    values = tags.values
    local, local_values = dolfinx.io.distribute_entity_data(
        new, fdim, entities if root else entities[:0], values if root else values[:0]
    )
    new.topology.create_connectivity(fdim, new.topology.dim)
    new_tags = dolfinx.mesh.meshtags_from_entities(
        new, fdim, dolfinx.graph.adjacencylist(local), local_values.astype(np.int32)
    )
    numbers = body.node_numbers()[new.geometry.input_global_indices]
    return Body(body.name, new, new_tags, body.boundaries, numbers)


def _mesh_geo(
    path: Path,
    parameters: dict[str, float],
    comm: MPI.Comm,
    cache: Path | None = None,
    refinements: int = 0,
) -> dolfinx.io.gmsh.MeshData:
    """Mesh ``path`` with gmsh on rank 0 and distribute it; errors are raised on every rank.

    With ``cache``, the mesh is read from (or written to) its ``.msh`` file there;
    ``refinements``: uniform refinements of the mesh gmsh makes.
    """
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such .geo file")
    text = path.read_text()
    for name in parameters:
        if not re.search(rf"\b{re.escape(name)}\b", text):
            raise ValueError(f"{path}: parameter '{name}' does not appear in the file")
    error, dim = None, 0
    # gmsh keeps a -setnumber value from one initialize to the next: pass every numeric
    # DefineConstant, its default unless given, so that an earlier load does not leak in
    defaults = re.findall(r"DefineConstant\[\s*(\w+)\s*=\s*([-+0-9.eE]+)\s*[;\]]", text)
    parameters = {name: float(value) for name, value in defaults} | dict(parameters)
    if comm.rank == 0:
        argv = ["gmsh"]
        for name, value in parameters.items():
            argv += ["-setnumber", name, repr(float(value))]
        gmsh.initialize(argv, interruptible=False)
        gmsh.option.setNumber("General.Terminal", 0)
        try:
            key = parameters | ({"refinements": refinements} if refinements else {})
            kept = _cached_mesh(cache, text, key, path) if cache is not None else None
            if kept is not None and kept.is_file():
                gmsh.open(str(kept))
                dim = gmsh.model.getDimension()
            else:
                gmsh.open(str(path))
                dim = gmsh.model.getDimension()
                gmsh.model.mesh.generate(dim)
                for _ in range(refinements):
                    gmsh.model.mesh.refine()
                if kept is not None:
                    _write_mesh(kept)
            if dim < 2 or not gmsh.model.getPhysicalGroups(dim):
                error = f"{path}: no {dim}D physical group: name the bodies with Physical groups"
            error = error or _stray_facet_group(path, dim) or _overlapping_groups(path, dim)
        except Exception as exc:
            error = f"{path}: gmsh could not mesh the file: {exc}"
    error, dim = comm.bcast((error, dim), root=0)
    if error is not None:
        if comm.rank == 0:
            gmsh.finalize()
        raise ValueError(error)
    try:
        model = gmsh.model if comm.rank == 0 else None
        return dolfinx.io.gmsh.model_to_mesh(model, comm, 0, gdim=dim)
    finally:
        if comm.rank == 0:
            gmsh.finalize()


def _cached_mesh(cache: Path, text: str, parameters: dict[str, float], path: Path) -> Path:
    """The ``.msh`` file of this ``.geo`` text and these parameters in ``cache``."""
    key = repr((text, sorted(parameters.items()), gmsh.__version__)).encode()
    return cache / f"{path.stem}-{hashlib.sha256(key).hexdigest()[:16]}.msh"


def _write_mesh(kept: Path) -> None:
    """Write gmsh's current mesh to ``kept`` (whole, then renamed: ranks may race)."""
    kept.parent.mkdir(parents=True, exist_ok=True)
    partial = kept.with_name(f"{kept.stem}.{os.getpid()}.partial.msh")
    gmsh.option.setNumber("Mesh.Binary", 1)
    gmsh.write(str(partial))
    os.replace(partial, kept)


def _stray_facet_group(path: Path, dim: int) -> str | None:
    """A facet group with an entity that bounds no cell entity would crash the distribution."""
    for _, group in gmsh.model.getPhysicalGroups(dim - 1):
        for entity in gmsh.model.getEntitiesForPhysicalGroup(dim - 1, group):
            if len(gmsh.model.getAdjacencies(dim - 1, int(entity))[0]) == 0:
                name = gmsh.model.getPhysicalName(dim - 1, group)
                return (
                    f"{path}: physical group '{name}' has no facets on any body "
                    f"(its entity {entity} bounds no {dim}D entity)"
                )
    return None


def _overlapping_groups(path: Path, dim: int) -> str | None:
    """Two cell groups sharing an entity: a cell can carry one tag only, one group loses it."""
    seen: dict[int, str] = {}
    for _, group in gmsh.model.getPhysicalGroups(dim):
        name = gmsh.model.getPhysicalName(dim, group)
        for entity in gmsh.model.getEntitiesForPhysicalGroup(dim, group):
            other = seen.setdefault(int(entity), name)
            if other != name:
                kind = "surface" if dim == 2 else "volume"
                return (
                    f"{path}: physical groups '{other}' and '{name}' share {kind} {entity}: "
                    "a cell belongs to one group only (make the groups disjoint)"
                )
    return None


def _body_of_cell(
    cell_tags: dolfinx.mesh.MeshTags, body_tags: dict[str, int], parent: dolfinx.mesh.Mesh
) -> npt.NDArray[np.int32]:
    """Index into the scene's body list of every local cell (-1 where no listed body)."""
    cells = parent.topology.index_map(parent.topology.dim)
    owner = np.full(cells.size_local + cells.num_ghosts, -1, dtype=np.int32)
    for k, tag in enumerate(body_tags.values()):
        owner[cell_tags.find(tag)] = k
    return owner


def _make_body(
    parent: dolfinx.mesh.Mesh,
    data: dolfinx.io.gmsh.MeshData,
    name: str,
    tag: int,
    facet_groups: dict[str, int],
) -> Body:
    """Submesh of one body with the parent's facet tags carried over."""
    tdim = parent.topology.dim
    mesh, cell_map, vertex_map, _ = dolfinx.mesh.create_submesh(
        parent, tdim, data.cell_tags.find(tag)
    )
    mesh.topology.create_connectivity(tdim - 1, tdim)
    tags = dolfinx.mesh.transfer_meshtags_to_submesh(data.facet_tags, mesh, vertex_map, cell_map)
    num_owned = mesh.topology.index_map(tdim - 1).size_local
    present = {}
    for group, value in facet_groups.items():
        count = int(np.count_nonzero(tags.find(value) < num_owned))
        if mesh.comm.allreduce(count, op=MPI.SUM) > 0:
            present[group] = value
    return Body(name, mesh, tags, present)


def _make_interface(
    path: Path,
    parent: dolfinx.mesh.Mesh,
    facet_tags: dolfinx.mesh.MeshTags,
    name: str,
    tag: int,
    bodies: list[str],
    body_of_cell: npt.NDArray[np.int32],
) -> Interface:
    """Find the two bodies on either side of a facet group and build its master mesh."""
    tdim = parent.topology.dim
    facets = facet_tags.find(tag)  # local, ghosts included: a rank may see only one side
    num_owned = int(np.count_nonzero(facets < parent.topology.index_map(tdim - 1).size_local))
    if parent.comm.allreduce(num_owned, op=MPI.SUM) == 0:
        raise ValueError(f"{path}: interface '{name}' has no facets")
    linked, cells = _facet_cell_links(parent, facets)
    side = body_of_cell[cells]  # body index of each (facet, cell) link
    touched = set().union(*parent.comm.allgather(set(side.tolist())))
    if -1 in touched:
        raise ValueError(f"{path}: interface '{name}' touches a cell group that is not a body")
    if len(touched) != 2:
        names = [bodies[k] for k in sorted(touched)]
        raise ValueError(
            f"{path}: interface '{name}' must lie between exactly two bodies, it touches {names}"
        )
    first, second = sorted(touched)
    # The master mesh copies the first body's side (the whole group when facets are shared).
    on_side = linked[side == first]  # cells of `first` seen per facet, summed on its owner
    seen = _summed_on_owners(parent.topology.index_map(tdim - 1), on_side, np.ones(len(on_side)))
    on_first = np.flatnonzero(seen).astype(np.int32)
    master, *_ = dolfinx.mesh.create_submesh(parent, tdim - 1, on_first)
    return Interface(name, (bodies[first], bodies[second]), tag, master)


def _facet_cell_links(
    mesh: dolfinx.mesh.Mesh, facets: npt.NDArray[np.int32]
) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.int32]]:
    """Every (facet, cell) pair of the given local facets: the facet and the cell of each."""
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    f2c = mesh.topology.connectivity(tdim - 1, tdim)
    counts = f2c.offsets[facets + 1] - f2c.offsets[facets]
    starts = np.repeat(f2c.offsets[facets], counts)
    within = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    return np.repeat(facets, counts), f2c.array[starts + within]


def _summed_on_owners(
    index_map: dolfinx.common.IndexMap,
    entities: npt.NDArray[np.int32],
    values: npt.NDArray[np.float64],
) -> npt.NDArray[np.float64]:
    """Per owned entity, the sum of ``values`` added at local ``entities`` on every rank."""
    vector = dolfinx.la.vector(index_map, dtype=np.float64)
    np.add.at(vector.array, entities, values)
    vector.scatter_reverse(dolfinx.la.InsertMode.add)  # owners learn what ghosts saw
    return vector.array[: index_map.size_local].copy()


def _check_touching(
    path: Path,
    parent: dolfinx.mesh.Mesh,
    facet_tags: dolfinx.mesh.MeshTags,
    interface_tags: list[int],
    bodies: list[str],
    body_of_cell: npt.NDArray[np.int32],
) -> None:
    """Two bodies that share facets must have an interface there (else: solved as apart)."""
    tdim = parent.topology.dim
    facet_map = parent.topology.index_map(tdim - 1)
    local = np.arange(facet_map.size_local + facet_map.num_ghosts, dtype=np.int32)
    linked, cells = _facet_cell_links(parent, local)
    label = body_of_cell[cells] + 1.0  # 0 where the cell is in no body
    inside = label > 0
    # per facet: how many body cells, and the sums of x and x² of their labels x (the ranks
    # that see a facet's cells add theirs); two labels x ≠ y iff 2(x² + y²) − (x + y)² > 0
    count, first, second = (
        _summed_on_owners(facet_map, linked[inside], values[inside])
        for values in (np.ones_like(label), label, label**2)
    )
    interface = facet_tags.indices[np.isin(facet_tags.values, interface_tags)]
    tagged = _summed_on_owners(facet_map, interface, np.ones(len(interface)))
    spread = np.sqrt(np.maximum(2.0 * second - first**2, 0.0))
    touching = np.flatnonzero((count == 2) & (spread > 0.5) & (tagged == 0))
    total = parent.comm.allreduce(len(touching), op=MPI.SUM)
    if total == 0:
        return
    found = None
    if len(touching):
        f = touching[0]
        a, b = (
            round((first[f] - spread[f]) / 2) - 1,
            round((first[f] + spread[f]) / 2) - 1,
        )
        where = dolfinx.mesh.compute_midpoints(parent, tdim - 1, touching[:1].astype(np.int32))[0]
        found = (bodies[a], bodies[b], where)
    a, b, where = next(item for item in parent.comm.allgather(found) if item is not None)
    raise ValueError(
        f"{path}: bodies '{a}' and '{b}' touch ({total} facets, one at "
        f"{np.array2string(where, precision=4)}) with no interface between them: name their "
        "common boundary with a physical group and list it in interfaces= (or merge the two "
        "bodies into one group)"
    )


def _check_conforming(path: Path, interface: Interface, bodies: Mapping[str, Body]) -> None:
    """Every node of both sides must sit on a node of the master mesh, one to one."""
    master = gather_rows(interface.master_mesh.comm, _owned_vertex_coordinates(interface))
    for body_name in interface.bodies:
        body = bodies[body_name]
        fdim = body.mesh.topology.dim - 1
        facets = body.facet_tags.find(interface.tag)
        vertices = dolfinx.mesh.compute_incident_entities(body.mesh.topology, facets, fdim, 0)
        # A rank may own a vertex of the group without holding any of its facets: owners learn
        # from the ranks that hold them.
        seen = _summed_on_owners(body.mesh.topology.index_map(0), vertices, np.ones(len(vertices)))
        vertices = np.flatnonzero(seen).astype(np.int32)
        body.mesh.topology.create_connectivity(0, fdim + 1)
        nodes = dolfinx.mesh.entities_to_geometry(body.mesh, 0, vertices).ravel()
        side = gather_rows(body.mesh.comm, body.mesh.geometry.x[nodes])
        match_points(master, side, what=f"{path}: interface '{interface.name}', body '{body_name}'")


def _owned_vertex_coordinates(interface: Interface) -> npt.NDArray[np.float64]:
    mesh = interface.master_mesh
    vertices = np.arange(mesh.topology.index_map(0).size_local, dtype=np.int32)
    mesh.topology.create_connectivity(0, mesh.topology.dim)
    nodes = dolfinx.mesh.entities_to_geometry(mesh, 0, vertices).ravel()
    return mesh.geometry.x[nodes]


def gather_rows(comm: MPI.Comm, rows: npt.NDArray) -> npt.NDArray:
    """Concatenate every rank's rows, in rank order, on every rank."""
    return np.concatenate(comm.allgather(np.asarray(rows)))


def match_points(
    reference: npt.NDArray[np.float64], query: npt.NDArray[np.float64], *, what: str
) -> npt.NDArray[np.int64]:
    """Index of the reference point that each query point sits on (a one-to-one match).

    Args:
        reference: Points, shape ``(n, 3)``.
        query: Points, shape ``(n, 3)``.
        what: Names the interface in the error message.

    Raises:
        ValueError: The two point sets are not the same nodes (a non-conforming interface).
    """
    extent = float(np.ptp(reference, axis=0).max()) if len(reference) else 0.0
    tolerance = 1e-9 * max(extent, 1e-300)
    distance, index = cKDTree(reference).query(query)
    if len(query) != len(reference) or len(np.unique(index)) != len(query):
        raise ValueError(
            f"{what}: non-conforming interface: {len(query)} nodes on this side, "
            f"{len(reference)} on the master layer (the sides must share their nodes)"
        )
    if len(distance) and distance.max() > tolerance:
        worst = int(np.argmax(distance))
        raise ValueError(
            f"{what}: non-conforming interface: the node at {query[worst]} is "
            f"{distance[worst]:.3g} away from the nearest master node (tolerance {tolerance:.3g})"
        )
    return index
