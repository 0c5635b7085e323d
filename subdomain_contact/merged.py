"""The whole Jacobian as one matrix: bodies and master layers merged, assembled or not.

Unknowns ``[y^α ..., y_m,k ...]`` in the global-vector layout; blocks ``A^α`` (each body's
whole matrix), ``B^α_k P_k`` between a body and a master layer, ``P_kᵀ C^α_k`` back, and
``Σ_α P_kᵀ D^α_k P_k`` on each master layer. Masters of an insulating contact have no
equation: their rows hold the identity. Used by the monolithic reference and by the sparse
strip corrector (its rows and columns restricted to strips along the contacts).
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping

import numpy as np
import numpy.typing as npt
import scipy.sparse
from mpi4py import MPI
from petsc4py import PETSc

from subdomain_contact.solvers import destroy
from subdomain_contact.system import System

__all__ = [
    "VALUES_SLACK",
    "Layout",
    "MergePlan",
    "RestrictedPlan",
    "merged_matrix",
    "plan",
    "unassembled_matrix",
]


class Layout:
    """Global indices of the system's unknowns (the global-vector layout), on every rank."""

    def __init__(self, system: System) -> None:
        comm = system.comm
        offsets = np.cumsum([0, *comm.allgather(system.local_size)])
        self.size, self.mine = int(offsets[-1]), int(offsets[comm.rank])
        first = int(offsets[0]) + comm.bcast(system.master_slice.start, root=0)
        #: global index of the first master (rank 0 holds the master rows)
        self.first_master = first
        ends = np.cumsum([0, *system.sizes.values()])
        #: interface -> global index of its first master
        self.master_at = {k: first + int(e) for k, e in zip(system.sizes, ends[:-1], strict=True)}
        self._shifts = {}
        for name, body in system.bodies.items():
            ranges = np.asarray(body.A_bulk.getOwnershipRanges())
            shift = self.mine + system.slices[name].start - body.start
            self._shifts[name] = ranges, np.array(body.comm.allgather(shift))

    def body(self, name: str, g: npt.NDArray) -> npt.NDArray:
        """Global indices of a body's DOFs ``g`` (numbered on the body's communicator)."""
        ranges, shifts = self._shifts[name]
        return g + shifts[np.searchsorted(ranges, g, side="right") - 1]


Entries = tuple[npt.NDArray, npt.NDArray, npt.NDArray]  # rows, columns, values


def _body_entries(
    system: System,
    layout: Layout,
    name: str,
    place: npt.NDArray | None = None,
    reach: float | None = None,
) -> tuple[list[Entries], list[Entries]]:
    """A body's entries of the merged matrix, global indices, zeros included.

    Returns its rows on this rank (``A``, and ``B_k P_k`` to the masters), and its share of
    the master rows (``P_kᵀ C_k``, and ``P_kᵀ D_k P_k`` on the active masters; identity
    halves on an insulating channel's), given by the body's first rank only. With ``place``
    (each global index's place among the kept ones, -1 where not kept), only the entries
    whose row and column are kept, renumbered, the rows chosen before the body's entries
    are expanded to triples; with ``reach`` too, the entries to the body's dropped columns
    are lumped on the row's node (:func:`_lumped`) instead of dropped.
    """
    body = system.bodies[name]
    indptr, indices, data = body.whole_matrix().getValuesCSR()
    first_row = layout.mine + system.slices[name].start
    counts = np.diff(indptr)
    if place is None:
        rows = [(first_row + np.repeat(np.arange(body.size), counts),
                 layout.body(name, indices), data)]  # fmt: skip
    else:
        picked = place[first_row + np.arange(body.size)] >= 0
        entries = np.repeat(picked, counts)
        rows = [(first_row + np.repeat(np.flatnonzero(picked), counts[picked]),
                 layout.body(name, indices[entries]), data[entries])]  # fmt: skip
        if reach is not None:
            local = np.repeat(np.flatnonzero(picked), counts[picked])
            rows.append(_lumped(system, layout, name, place, local, indices[entries],
                                data[entries], reach))  # fmt: skip
    local, columns, values = _to_masters(system, layout, name)
    rows.append((first_row + local, columns, values))
    masters = _master_entries(system, layout, name)
    if place is not None:
        rows, masters = _restricted(rows, place), _restricted(masters, place)
    return rows, masters


def _to_masters(system: System, layout: Layout, name: str) -> Entries:
    """A body's ``B_k P_k`` on its owned free rows, sorted by row (stable).

    Returns (rows local to the body, global master columns, values).
    """
    body = system.bodies[name]
    owned = np.arange(body.kept_slice.start, body.kept_slice.stop)
    free = np.setdiff1d(owned, body.fixed_kept)  # a fixed row is its condition alone
    rows, columns, values = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)], [np.zeros(0)]
    for k in body.layers:
        B = body.blocks[k]["BP"][free].tocoo()
        rows.append(body.kept[free][B.row] - body.start)
        columns.append(layout.master_at[k] + B.col)
        values.append(B.data)
    rows, columns, values = (np.concatenate(a) for a in (rows, columns, values))
    order = np.argsort(rows, kind="stable")
    return rows[order], columns[order], values[order]


def _master_entries(system: System, layout: Layout, name: str) -> list[Entries]:
    """A body's share of the master rows (given by its first rank only)."""
    body, masters = system.bodies[name], []
    kept = layout.body(name, body.kept)
    for k in body.layers:
        blocks, at = body.blocks[k], layout.master_at[k]
        if body.comm.rank == 0:
            # the parts' entries side by side, summed when the matrix is made: a sparse sum
            # here would drop the entries that happen to cancel or vanish at this state
            # (scipy keeps no computed zeros), and the pattern would change with the state.
            # The masters' columns of fixed DOFs are left out, as the fixed rows' entries
            # are (Newton's increments vanish there): the matrix keeps the system's
            # symmetry, which GAMG needs (the slot's displacement block had 180 eigenvalues
            # near −74, Jacobi-scaled, on fixed slaves and their masters)
            at_k = body.position[k]
            for C in [-blocks["L"][at_k]] + ([blocks["CtP"]] if "CtP" in blocks else []):
                C = C.tocoo()
                moving = np.isin(C.col, body.free_kept)
                masters.append((at + C.row[moving], kept[C.col[moving]], C.data[moving]))
            # P_kᵀ D_k P_k, sparse (the half-link's mass-like block), its stored pattern
            # whole; an inactive master row and column hold 1/2 on the diagonal alone
            active = system.active[k]
            for D in [-blocks["BP"][at_k]] + ([blocks["DtP"]] if "DtP" in blocks else []):
                D = D.tocoo()
                both = active[D.row] & active[D.col]
                masters.append((at + D.row[both], at + D.col[both], D.data[both]))
            idle = np.flatnonzero(~active)
            masters.append((at + idle, at + idle, np.full(idle.size, 0.5)))
    return masters


def _lumped(
    system: System,
    layout: Layout,
    name: str,
    place: npt.NDArray,
    rows: npt.NDArray,
    columns: npt.NDArray,
    values: npt.NDArray,
    reach: float,
) -> Entries:
    """The kept rows' entries to dropped columns, as a Robin condition on the cut.

    Restricted to the kept rows and columns, the body would be clamped at the first node
    beyond the cut: a stiffness of one element layer where the body goes on. A dropped
    node j at distance d from the row's node i is taken to follow it, ``y_j = (1 − θ) y_i``
    component by component, with ``θ = d / (d + reach)``: the element's link to j in series
    with ``reach`` more of the body to where it is held, so that the cut answers a mode of
    wavenumber ``1 / reach`` as the whole body would (a slab of width w with the Robin
    coefficient k ξ behind it has the half-space's response k ξ at ξ; clamped, k ξ coth ξw).
    Where the row's and the column's components differ, the node's block is made symmetric
    for a symmetric system (CG) only: unsymmetric, it keeps the body's rigid translations
    (with ``reach`` → ∞ a translation is in the kernel of the strip's rows but the
    contacts', as of the body's). ``rows``: the kept rows' owned local indices, one per
    entry; ``columns``: the entries' columns (the body's global numbering). Columns this
    rank does not hold (a body spread over ranks, across a rank boundary), and entries that
    would land on a DOF fixed by a Dirichlet condition, stay dropped.
    """
    body = system.bodies[name]
    outside = place[layout.body(name, columns)] < 0
    rows, columns, values = rows[outside], columns[outside], values[outside]
    local = _local_dofs(body, columns)
    held = local >= 0
    rows, local, values = rows[held], local[held], values[held]
    nodes = body.forms.nodes()
    i, j = nodes.node[rows], nodes.node[local]
    distance = np.linalg.norm(nodes.points[i] - nodes.points[j], axis=1)
    follows = values / (1.0 + distance / reach)  # (1 − θ) a_ij
    target = nodes.dof_at[i, nodes.component[local]]  # an owned node's: owned
    free = ~np.isin(target, body.fixed_local)  # a fixed DOF's row stays its condition alone
    rows, target, follows = rows[free], target[free], follows[free]
    first_row = layout.mine + system.slices[name].start
    if not system.symmetric:
        return first_row + rows, first_row + target, follows
    r = np.concatenate([first_row + rows, first_row + target])
    c = np.concatenate([first_row + target, first_row + rows])
    return r, c, np.concatenate([follows, follows]) / 2


def _local_dofs(body, columns: npt.NDArray) -> npt.NDArray:
    """Local indices (owned, then ghosts; unrolled) of global DOF numbers; -1 if not held."""
    index_map, bs = body.forms.W.dofmap.index_map, body.forms.W.dofmap.index_map_bs
    local = np.full(columns.size, -1, dtype=np.int64)
    owned = (columns >= body.start) & (columns < body.start + body.size)
    local[owned] = columns[owned] - body.start
    ghosts = np.asarray(index_map.ghosts, dtype=np.int64)
    if ghosts.size and not owned.all():
        order = np.argsort(ghosts)
        blocks, parts = np.divmod(columns[~owned], bs)
        at = np.clip(np.searchsorted(ghosts[order], blocks), 0, ghosts.size - 1)
        found = ghosts[order][at] == blocks
        ghost_local = bs * (index_map.size_local + order[at]) + parts
        local[~owned] = np.where(found, ghost_local, -1)
    return local


def _restricted(parts: list[Entries], place: npt.NDArray) -> list[Entries]:
    """The entries whose row and column are kept, renumbered to their places."""
    out = []
    for r, c, v in parts:
        pr, pc = place[r], place[c]
        inside = (pr >= 0) & (pc >= 0)
        out.append((pr[inside], pc[inside], v[inside]))
    return out


def _concatenate(parts: list[Entries]) -> Entries:
    """One (rows, columns, values) triple of many."""
    if not parts:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0)
    r, c, v = (np.concatenate([part[i] for part in parts]) for i in range(3))
    return r, c, v


def _aij(
    rows: npt.NDArray, columns: npt.NDArray, values: npt.NDArray, shape, size, comm
) -> PETSc.Mat:
    """An AIJ matrix of ``size`` from this rank's entries (local rows, global columns).

    Duplicates are summed; explicit zeros are kept.
    """
    csr = scipy.sparse.coo_matrix((values, (rows, columns)), shape=shape).tocsr()
    csr.sort_indices()
    return PETSc.Mat().createAIJ(
        size=size,
        csr=(csr.indptr.astype(PETSc.IntType), csr.indices.astype(PETSc.IntType), csr.data),
        comm=comm,
    )


#: The allocator's slack over the arrays :meth:`MergePlan.values` holds at its peak
#: (:attr:`MergePlan.values_bytes`). On the collector bar slot at 65,900 DOFs the arrays
#: counted came to 26.7 bytes an entry and numpy's allocations traced to 24.9: a third more
#: for the allocator and the resident set beyond numpy's arrays.
VALUES_SLACK = 4 / 3

#: Entries renumbered or moved at once: bounds the int64 temporaries of the whole-matrix
#: build (about 32 bytes an entry) to about 32 MB.
_CHUNK = 1 << 20

Block = tuple[int, npt.NDArray, npt.NDArray, npt.NDArray]  # first row, indptr, indices, data


def _blocks(system: System, layout: Layout, digest):
    """This rank's blocks of the merged matrix at the current state, body by body.

    Yields (name, ``A``'s CSR arrays (indptr, indices local to the body, data), ``B_k P_k``
    as (rows local to the body, global master columns, values), the body's parts of the
    master rows as (global rows, global columns, values) triples, none but on the body's
    first rank), every stored entry, zeros included; each body's index arrays are added to
    ``digest`` (:func:`_digest`) before it is yielded.
    """
    for name in system.bodies:
        A = system.bodies[name].whole_matrix().getValuesCSR()
        to_masters = _to_masters(system, layout, name)
        parts = _master_entries(system, layout, name)
        for array in (*A[:2], *to_masters[:2], *(x for p in parts for x in p[:2])):
            digest.update(np.ascontiguousarray(array))
        yield name, A, to_masters, parts


def _digest(system: System, layout: Layout):
    """A digest of the blocks' index arrays (:func:`_blocks`), seeded with the sizes.

    SHA-256: 1.8 GB/s here, blake2b 0.8.
    """
    digest = hashlib.sha256()
    digest.update(np.array([layout.size, system.local_size], dtype=np.int64))
    return digest


class MergePlan:
    """The whole merged matrix's pattern on this rank, and where each block entry goes in it.

    Made from the blocks at one state: each body's rows (``A`` with its columns renumbered,
    ``B_k P_k`` spliced onto the contact rows) and the master rows (summed over the bodies,
    rank 0) with a code for each entry in place of its value, sorted by column in each row,
    the codes read back as positions. :meth:`values` then scatters the blocks' values at any
    state whose blocks store the same entries (a digest of every rank's block patterns),
    with no sort and no COO sum: at 221k DOFs on 2 ranks the merge had taken 1.35 s a
    Newton step beside its 0.37 s of assembly. Held: the pattern (``indptr``, ``indices``)
    and the positions, about 8 bytes an entry. Collective.
    """

    def __init__(self, system: System) -> None:
        comm, layout = system.comm, Layout(system)
        digest = _digest(system, layout)
        blocks: list[Block] = []
        masters = []
        codes = 0  # this rank's body-row values, in the order of :func:`_blocks`
        index = PETSc.IntType
        largest = 0  # bytes of one body's blocks read at once (:attr:`values_bytes`)
        for name, A, to_masters, parts in _blocks(system, layout, digest):
            (indptr, indices, a), (rows, columns, values) = A, to_masters
            read = (*A, *to_masters, *(x for p in parts for x in p))
            largest = max(largest, sum(x.nbytes for x in read))
            for start in range(0, indices.size, _CHUNK):
                part = slice(start, start + _CHUNK)
                indices[part] = layout.body(name, indices[part])
            at = np.arange(codes, codes + a.size, dtype=np.float64)
            to = np.arange(codes + a.size, codes + a.size + values.size, dtype=np.float64)
            codes += a.size + values.size
            # each appended entry after its row's entries (ties in order)
            indices, at = _spliced((indices, at), indptr[rows + 1], (columns, to))
            added = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=len(indptr) - 1))])
            blocks.append((system.slices[name].start, indptr + added, indices, at))
            # compact at once: the master rows hold a third of the slot's entries
            masters += [((r - layout.first_master).astype(index), c.astype(index))
                        for r, c, _ in parts]  # fmt: skip
            parts.clear()
        self.pattern = tuple(comm.allgather(digest.digest()))
        own = sum(r.size for r, _ in masters)  # this rank's master-row parts' entries
        self._own, self._counts = own, comm.gather(own, root=0)  # each rank's, on rank 0
        self._master_of: npt.NDArray | None = None  # rank 0: each master entry's place
        gathered = comm.gather(masters, root=0)
        masters.clear()
        first, stop = system.master_slice.start, system.master_slice.stop
        if comm.rank == 0 and stop > first:
            r, c = (np.concatenate([p[i] for ps in gathered for p in ps]) for i in (0, 1))
            gathered.clear()
            key = r.astype(np.int64) * layout.size + c
            del r, c
            unique, inverse = np.unique(key, return_inverse=True)  # row by row, columns sorted
            del key
            self._master_of = inverse.astype(_positions(unique.size))
            del inverse
            indptr = np.concatenate(
                [[0], np.cumsum(np.bincount(unique // layout.size, minlength=stop - first))]
            )
            codes_m = np.arange(codes, codes + unique.size, dtype=np.float64)
            blocks.append((first, indptr, (unique % layout.size).astype(PETSc.IntType), codes_m))
            del unique
        blocks.sort(key=lambda block: block[0])
        starts = np.cumsum([0, *(len(block[1]) - 1 for block in blocks)])
        if [block[0] for block in blocks] != list(starts[:-1]) or starts[-1] != system.local_size:
            raise AssertionError(
                f"merged matrix: row blocks {[(b[0], len(b[1]) - 1) for b in blocks]} on rank "
                f"{comm.rank} do not tile its {system.local_size} rows"
            )
        ends = np.cumsum([0, *(block[2].size for block in blocks)])
        indptr = np.concatenate(
            [[0]] + [block[1][1:] + end for block, end in zip(blocks, ends, strict=False)]
        ).astype(PETSc.IntType)
        indices = np.concatenate([block[2] for block in blocks]).astype(PETSc.IntType, copy=False)
        data = np.concatenate([block[3] for block in blocks])
        blocks.clear()
        csr = scipy.sparse.csr_matrix(
            (data, indices, indptr), shape=(system.local_size, layout.size), copy=False
        )
        csr.sort_indices()  # in place, on these arrays: the codes follow their entries
        self.indptr, self.indices = csr.indptr, csr.indices
        nnz = self.indices.size
        where = np.empty(nnz, dtype=_positions(nnz))
        where[csr.data.astype(np.int64)] = np.arange(nnz, dtype=where.dtype)
        del csr, data
        self._body_at, self._master_at = where[:codes].copy(), where[codes:].copy()
        received = sum(self._counts) + self._master_at.size if comm.rank == 0 else 0
        #: Bytes :meth:`values` holds at its peak on this rank, slack included: the values
        #: with, in turn, one body's blocks as read and this rank's master-row values so far,
        #: those values sent (and their parts), or those sent with, on rank 0, all of them
        #: received and their sums.
        self.values_bytes = VALUES_SLACK * (
            8 * nnz + max(largest + 8 * own, 16 * own, 8 * own + 8 * received)
        )

    @property
    def nnz(self) -> int:
        """This rank's stored entries."""
        return int(self.indices.size)

    def values(self, system: System) -> npt.NDArray | None:
        """The merged matrix's values on this rank at the system's state, in the plan's pattern.

        None (on every rank) where the blocks store other entries. Collective.
        """
        comm, layout = system.comm, Layout(system)
        digest = _digest(system, layout)
        data, at, fits, masters = np.empty(self.nnz), 0, True, []
        for _, (_, _, a), (_, _, values), parts in _blocks(system, layout, digest):
            for x in (a, values):
                fits = fits and at + x.size <= self._body_at.size
                if fits:
                    data[self._body_at[at : at + x.size]] = x
                at += x.size
            masters += [v for _, _, v in parts]
            parts.clear()  # their rows and columns freed
        fits = fits and at == self._body_at.size
        send = np.concatenate([np.zeros(0), *masters])
        masters.clear()
        seen = comm.allgather((digest.digest(), fits and send.size == self._own))
        if tuple(d for d, _ in seen) != self.pattern or not all(f for _, f in seen):
            return None
        received = np.empty(sum(self._counts)) if comm.rank == 0 else None
        comm.Gatherv(send, (received, self._counts) if comm.rank == 0 else None, root=0)
        del send
        if self._master_of is not None:
            data[self._master_at] = np.bincount(self._master_of, received, self._master_at.size)
        return data

    def matrix(self, comm: MPI.Comm, data: npt.NDArray) -> PETSc.Mat:
        """A new AIJ matrix of the plan's pattern holding ``data`` (collective)."""
        n = (len(self.indptr) - 1, PETSc.DETERMINE)
        return PETSc.Mat().createAIJ(size=(n, n), csr=(self.indptr, self.indices, data), comm=comm)

    def write(self, K: PETSc.Mat, data: npt.NDArray) -> None:
        """Write ``data`` into ``K`` of the plan's pattern, in place (collective)."""
        K.setValuesCSR(self.indptr, self.indices, data, addv=PETSc.InsertMode.INSERT_VALUES)
        K.assemble()


def _positions(n: int) -> type:
    """The smallest of int32 and int64 that indexes ``n`` entries."""
    return np.int32 if n < 2**31 else np.int64


def _spliced(
    arrays: tuple[npt.NDArray, ...], at: npt.NDArray, inserted: tuple[npt.NDArray, ...]
) -> list[npt.NDArray]:
    """``np.insert(a, at, v)`` for each pair of arrays and values, ``at`` sorted.

    Inserted values before ``a[at]``, ties in their order; without ``np.insert``'s index
    array of every entry (8 bytes an entry): the old entries are moved by chunks.
    """
    n = len(arrays[0])
    out = [np.empty(n + len(at), a.dtype) for a in arrays]
    for new, values in zip(out, inserted, strict=True):
        new[at + np.arange(len(at))] = values
    for start in range(0, n, _CHUNK):
        old = np.arange(start, min(start + _CHUNK, n))
        moved = old + np.searchsorted(at, old, side="right")
        for new, a in zip(out, arrays, strict=True):
            new[moved] = a[start : start + _CHUNK]
    return out


class RestrictedPlan:
    """The merged matrix restricted to some rows and their columns (the sparse strip's).

    Its pattern is made once, with where each entry of a state goes in it. The entries of a
    state (:func:`_body_entries` with the kept rows' places, in a fixed order) are summed
    into the pattern by their places (``np.bincount``): no sort, where the COO-to-CSR
    conversion at every Newton step had cost rank 0 1.5 s a Jacobian (cProfile) on the
    collector bar slot at 203,925 DOFs. :meth:`values` is None where the entries stored
    differ (a digest of every rank's rows and columns), as :class:`MergePlan`'s. ``reach``:
    as :func:`merged_matrix`'s. Collective.

    The sparse strip keeps its plan, and the whole one (:class:`MergePlan`) where its
    layers cover every row, which it had made again at every Jacobian. The nested slot,
    constant setup, the subdomain Newton with the strip split, 2 ranks (two runs each,
    alternated, 2026-12-04): its two coarser levels (11,530 and 45,695 DOFs, the strip
    covering them) 26.6–26.9 s against 30.6–30.8 s; its fine level 113.4–123.8 s against
    120.6–122.6 s, within the runs' spread (the other rank's work sets its pace).
    """

    def __init__(
        self, system: System, rows: npt.NDArray, reach: Mapping[str, float] | None = None
    ) -> None:
        comm, layout = system.comm, Layout(system)
        keep = np.concatenate(comm.allgather(np.asarray(rows, np.int64)))
        self.size, self.reach = keep.size, reach
        self._place = np.full(layout.size, -1, dtype=np.int64)  # each row's place, or -1
        self._place[keep] = np.arange(keep.size)
        self._first = comm.exscan(len(rows)) or 0
        self._local = len(rows)
        r, c, _, digest = self._entries(system)
        self.pattern = tuple(comm.allgather(digest))
        key = (r - self._first) * keep.size + c
        del r, c
        unique, where = np.unique(key, return_inverse=True)  # row by row, columns sorted
        del key
        self._where = where.astype(_positions(unique.size))
        del where
        counts = np.bincount(unique // keep.size, minlength=self._local)
        self.indptr = np.concatenate([[0], np.cumsum(counts)]).astype(PETSc.IntType)
        self.indices = (unique % keep.size).astype(PETSc.IntType)

    def _entries(self, system: System) -> tuple[npt.NDArray, npt.NDArray, npt.NDArray, bytes]:
        """This rank's entries (rows numbered among the kept, columns too) and their digest."""
        comm, layout = system.comm, Layout(system)
        entries, masters = [], []
        for name in system.bodies:
            cut = None if self.reach is None else self.reach.get(name)
            body_rows, body_masters = _body_entries(system, layout, name, self._place, cut)
            entries += body_rows
            masters += body_masters
        gathered = comm.gather(masters, root=0)
        if comm.rank == 0:
            entries += [part for parts in gathered for part in parts]
        r, c, v = _concatenate(entries)
        digest = hashlib.sha256(np.array([self.size, r.size], dtype=np.int64))
        digest.update(np.ascontiguousarray(r))
        digest.update(np.ascontiguousarray(c))
        return r, c, v, digest.digest()

    @property
    def nnz(self) -> int:
        """This rank's stored entries."""
        return int(self.indices.size)

    def values(self, system: System) -> npt.NDArray | None:
        """The restricted matrix's values on this rank at the system's state, in its pattern.

        None (on every rank) where the entries stored differ. Collective.
        """
        _, _, v, digest = self._entries(system)
        if tuple(system.comm.allgather(digest)) != self.pattern:
            return None
        return np.bincount(self._where, v, minlength=self.nnz)

    def matrix(self, comm: MPI.Comm, data: npt.NDArray) -> PETSc.Mat:
        """A new AIJ matrix of the plan's pattern holding ``data`` (collective)."""
        n = (self._local, PETSc.DETERMINE)
        return PETSc.Mat().createAIJ(size=(n, n), csr=(self.indptr, self.indices, data), comm=comm)

    write = MergePlan.write


def plan(
    system: System, rows: npt.NDArray | None = None, reach: Mapping[str, float] | None = None
) -> MergePlan | RestrictedPlan:
    """The plan of the merged matrix, or of it restricted to ``rows``. Collective.

    :class:`RestrictedPlan` on ``rows``; :class:`MergePlan` without them, or where every
    rank keeps every row.
    """
    if rows is not None:
        kept = system.comm.allreduce(len(rows))
        if kept < system.comm.allreduce(system.local_size):
            return RestrictedPlan(system, rows, reach)
    return MergePlan(system)


def merged_matrix(
    system: System, rows: npt.NDArray | None = None, reach: Mapping[str, float] | None = None
) -> PETSc.Mat:
    """The whole Jacobian as one AIJ matrix on the system's communicator.

    Rows and columns follow the global-vector layout, for bodies spread over every rank or
    held by rank groups alike. Each rank writes its bodies' rows; the master rows, summed over
    the bodies, go to rank 0. Every stored entry is kept, zeros included, so that the matrix
    keeps one sparsity pattern from one Newton step to the next.

    ``rows``: this rank's rows to keep (sorted global indices, owned here): the matrix is then
    restricted to them, rows and columns, numbered in their order over the ranks (as
    ``createSubMatrix`` numbers them), without the whole being made (the sparse strip of the
    collector bar slot at 1.07M DOFs: the whole merged matrix had doubled a rank's resident
    set, 6.1 to 11.4 GiB, for a strip of 228k of its rows). ``reach``: body name -> the
    length [m] of a Robin condition on that body's cut (:func:`_lumped`); a body not named
    is clamped beyond its kept rows. Made by its :func:`plan`, which a caller that makes it
    again at other states keeps.
    """
    made = plan(system, rows, reach)
    return made.matrix(system.comm, made.values(system))


def unassembled_matrix(system: System) -> PETSc.Mat:
    """The whole Jacobian left unassembled (MATIS): each rank its bodies and their masters.

    The local matrix holds the bodies' rows and their shares of the master rows; PETSc sums
    the shares of a master layer between two ranks, which is the merged matrix.
    """
    comm, layout = system.comm, Layout(system)
    parts = []
    for name in system.bodies:
        rows, masters = _body_entries(system, layout, name)
        parts += rows + masters
    # local unknowns: ranges of global indices (each body's, each touched layer's masters),
    # numbered in increasing global order
    ranges = [(layout.mine + system.slices[name].start, body.size)
              for name, body in system.bodies.items()]  # fmt: skip
    touched = {k for body in system.bodies.values() for k in body.layers}
    ranges += [(layout.master_at[k], system.sizes[k]) for k in system.sizes if k in touched]
    ranges.sort()
    first = np.array([a for a, _ in ranges])
    offset = first - np.cumsum([0, *(n for _, n in ranges)])[:-1]

    def local(g: npt.NDArray) -> npt.NDArray:
        return g - offset[np.searchsorted(first, g, side="right") - 1]

    r, c, v = _concatenate(parts)
    size = sum(n for _, n in ranges)
    block = _aij(local(r), local(c), v, (size, size), (size, size), MPI.COMM_SELF)
    numbers = np.concatenate([np.arange(a, a + n) for a, n in ranges]) if ranges else []
    lgmap = PETSc.LGMap().create(np.asarray(numbers, dtype=PETSc.IntType), comm=comm)
    n = (system.local_size, PETSc.DETERMINE)
    K = PETSc.Mat().createIS((n, n), lgmapr=lgmap, lgmapc=lgmap, comm=comm)
    K.setISLocalMat(block)
    K.assemble()
    destroy(block, lgmap)
    return K
