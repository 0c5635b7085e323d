"""What a transient run leaves behind: probes per step, a VTK series, checkpoints, progress.

A :class:`History` watches a :class:`~subdomain_contact.transient.Stepper` (give its
:meth:`History.after_step` to :meth:`~subdomain_contact.transient.Stepper.march`). After every
step it appends a row to ``history.csv`` and ``history.json`` (step, time, its length, steps
taken again so far, Newton iterations, inner rounds, factorisations, wall time, and each
probe's value) and prints a progress line;
every ``vtk_every`` steps and at ``vtk_times`` it writes the scene for ParaView to
``vtk/step_<n>/`` and rewrites ``series.pvd``, which holds every written time; every
``checkpoint_every`` steps, and when the process receives SIGINT or SIGTERM, it writes a
checkpoint (:mod:`~subdomain_contact.checkpoint`), and after a signal it stops the march.
:meth:`History.start` with ``restart=True`` resumes from the latest checkpoint: the rows and
VTK steps after it are dropped, so that no step is lost or repeated. :meth:`History.plot`
draws each probe against time.
"""

from __future__ import annotations

import csv
import io
import json
import shutil
import signal
import sys
import time as clock
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

from mpi4py import MPI

from subdomain_contact import checkpoint
from subdomain_contact.io import write_series, write_vtk
from subdomain_contact.newton import Result
from subdomain_contact.transient import Stepper

__all__ = ["History"]

#: Probes: a collective function of the system that returns the values to record, by name
#: (with the unit), the same names at every step.
Probes = Callable[..., Mapping[str, float]]

#: Columns of every row before the probes.
COLUMNS = (
    "step",
    "time [s]",
    "step [s]",
    "rejected",
    "newton",
    "rounds",
    "factorisations",
    "wall [s]",
)


class History:
    """Rows, VTK series and checkpoints of a transient run in ``directory``.

    Args:
        directory: Output folder (created).
        stepper: The stepper whose steps are recorded.
        probes: The values to record at every step, from the system: e.g.
            ``lambda s: {"current [A]": sc.current(s, "top")}``.
        until: The run's end time [s], for the progress line's share and ETA.
        vtk_every: Write the scene every this many steps (0: never).
        vtk_times: Also at these times [s] (give them to ``march(land_on=...)``).
        checkpoint_every: Write a checkpoint every this many steps (0: only on a signal).
        quiet: No progress line.
    """

    def __init__(
        self,
        directory: str | Path,
        stepper: Stepper,
        probes: Probes,
        *,
        until: float,
        vtk_every: int = 0,
        vtk_times: Sequence[float] = (),
        checkpoint_every: int = 0,
        quiet: bool = False,
    ) -> None:
        self.directory, self.stepper, self.probes = Path(directory), stepper, probes
        self.comm: MPI.Comm = stepper.system.comm
        self.until, self.vtk_every, self.vtk_times = until, vtk_every, sorted(vtk_times)
        self.checkpoint_every, self.quiet = checkpoint_every, quiet
        self.rows: list[dict] = []
        self.interrupted = False
        self._saved = -1  # the step of the latest checkpoint
        self._signal = False
        self._handlers: dict = {}
        self._wall = 0.0  # wall time of the run before this process
        self._start, self._began = clock.perf_counter(), stepper.time

    # -- start and stop -------------------------------------------------------------------
    def start(self, *, restart: bool = False) -> bool:
        """Open the run's files; with ``restart``, resume from the latest checkpoint.

        Returns:
            Whether a checkpoint was loaded (False: a fresh run, files emptied).
        """
        found = checkpoint.latest(self.directory / "checkpoints", self.comm) if restart else None
        if restart and found is None:
            where = self.directory / "checkpoints"
            self._say(f"no checkpoint in {where}: a fresh run", always=True)
        if found is None:
            if self.comm.rank == 0:
                for stale in ("history.csv", "history.json", "series.pvd", "vtk", "checkpoints"):
                    path = self.directory / stale
                    shutil.rmtree(path) if path.is_dir() else path.unlink(missing_ok=True)
                self.directory.mkdir(parents=True, exist_ok=True)
            self.rows = []
        else:
            self._resume(found)
        self._write_rows()
        self._catch_signals()
        self._start, self._began = clock.perf_counter(), self.stepper.time
        return found is not None

    def _resume(self, folder: Path) -> None:
        stepper = self.stepper
        numbers, arrays, master_arrays = checkpoint.load(folder, stepper.system)
        stepper.set_clock(numbers, arrays.get("past", []), master_arrays.get("past"))
        self._wall = numbers["wall"]
        rows = json.loads((self.directory / "history.json").read_text())["rows"]
        self.rows = [row for row in rows if row["step"] <= stepper.steps]
        if self.comm.rank == 0:  # VTK steps after the checkpoint are dropped
            for written in (self.directory / "vtk").glob("step_*"):
                if int(written.name.split("_")[1]) > stepper.steps:
                    shutil.rmtree(written)
        self._write_series()
        self._say(
            f"restarted from {folder} at t = {stepper.time:.6g} s, step {stepper.steps}",
            always=True,
        )

    def _catch_signals(self) -> None:
        def caught(number, frame):
            self._signal = True

        for number in (signal.SIGINT, signal.SIGTERM):
            try:
                self._handlers[number] = signal.signal(number, caught)
            except ValueError:  # not the main thread: signals stay with the caller
                pass

    def finish(self) -> None:
        """Restore the signal handlers; write the last rows, a checkpoint and the plot.

        The final checkpoint lets a later run go on from here (``restart`` with a later end).
        """
        for number, handler in self._handlers.items():
            signal.signal(number, handler)
        self._handlers = {}
        self._write_rows()
        if self.stepper.steps > 0 and self._saved != self.stepper.steps:
            self.save()
        if self.rows:
            self.plot(self.directory / "history.png")

    # -- every step -----------------------------------------------------------------------
    def after_step(self, stepper: Stepper, result: Result) -> bool:
        """Record the step; write VTK and checkpoints when due. True: stop (a signal came)."""
        wall = self._wall + clock.perf_counter() - self._start
        row = {
            "step": stepper.steps,
            "time [s]": stepper.time,
            "step [s]": stepper.last_step,
            "rejected": stepper.rejected,
            "newton": result.iterations,
            "rounds": result.rounds,
            "factorisations": result.factorisations,
            "wall [s]": wall,
        }
        values = {name: float(v) for name, v in self.probes(stepper.system).items()}
        if self.rows and set(values) != set(self.rows[0]) - set(COLUMNS):
            raise ValueError(f"History: the probes must name the same values at every step: "
                             f"{sorted(values)}")  # fmt: skip
        self.rows.append(row | values)
        self._write_rows()
        due = self.vtk_every and stepper.steps % self.vtk_every == 0
        due = due or any(abs(stepper.time - t) <= 1e-9 * max(abs(t), 1.0) for t in self.vtk_times)
        if due or stepper.time >= self.until * (1 - 1e-12):
            write_vtk(self._vtk_folder(stepper.steps), stepper.system, stepper.time)
            self._write_series()
        self._progress(row)
        stop = bool(self.comm.allreduce(self._signal, op=MPI.LOR))
        if stop or (self.checkpoint_every and stepper.steps % self.checkpoint_every == 0):
            folder = self.save()
            if stop:
                self.interrupted = True
                self._say(f"stopped by a signal at t = {stepper.time:.6g} s; state in {folder}; "
                          "run again with --restart to go on", always=True)  # fmt: skip
        return stop

    def save(self) -> Path:
        """Write a checkpoint of the stepper and its system now (collective)."""
        stepper = self.stepper
        numbers = stepper.clock() | {"wall": self._wall + clock.perf_counter() - self._start}
        past = {"past": [states for _, states in stepper.past]}
        self._saved = stepper.steps
        return checkpoint.save(
            self.directory / "checkpoints",
            stepper.system,
            numbers,
            past,
            {"past": stepper.past_masters},
        )

    # -- files ----------------------------------------------------------------------------
    def _vtk_folder(self, step: int) -> Path:
        return self.directory / "vtk" / f"step_{step:06d}"

    def _write_series(self) -> None:
        scenes = sorted((self.directory / "vtk").glob("step_*/scene.pvd"))
        scenes = self.comm.bcast(scenes if self.comm.rank == 0 else None, root=0)
        if scenes:
            write_series(self.directory / "series.pvd", scenes, self.comm)

    def _write_rows(self) -> None:
        if self.comm.rank != 0 or not self.rows:
            return
        self.directory.mkdir(parents=True, exist_ok=True)
        columns = list(self.rows[0])
        table = io.StringIO(newline="")
        writer = csv.DictWriter(table, columns)
        writer.writeheader()
        writer.writerows(self.rows)
        checkpoint.write_whole(self.directory / "history.csv", table.getvalue())
        document = {"columns": columns, "rows": self.rows}
        checkpoint.write_whole(self.directory / "history.json", json.dumps(document, indent=1))

    def plot(self, png: str | Path) -> Path:
        """Each probe against time, one panel per probe (rank 0 draws)."""
        names = [c for c in self.rows[0] if c not in COLUMNS] if self.rows else []
        if self.comm.rank == 0 and names:
            import matplotlib

            matplotlib.use("Agg")
            import matplotlib.pyplot as plt

            n = len(names)
            figure, axes = plt.subplots(n, 1, figsize=(7, 2.2 * n), sharex=True, squeeze=False)
            hours = [row["time [s]"] / 3600 for row in self.rows]
            for ax, name in zip(axes[:, 0], names, strict=True):
                ax.plot(hours, [row[name] for row in self.rows], ".-")
                ax.set_ylabel(name, fontsize=8)
                ax.grid(True, alpha=0.3)
            axes[-1, 0].set_xlabel("time [h]")
            figure.tight_layout()
            figure.savefig(png, dpi=110)
            plt.close(figure)
        self.comm.barrier()
        return Path(png)

    # -- terminal -------------------------------------------------------------------------
    def _progress(self, row: dict) -> None:
        elapsed = clock.perf_counter() - self._start
        done = row["time [s]"] / self.until if self.until > 0 else 1.0
        rate = (row["time [s]"] - self._began) / elapsed if elapsed > 0 else 0.0
        eta = (self.until - row["time [s]"]) / rate if rate > 0 else float("nan")
        self._say(
            f"t = {row['time [s]']:.4g} s ({100 * done:5.1f} %)  step {row['step']}  "
            f"Δt {row['step [s]']:.3g} s ({row['rejected']} taken again)  "
            f"Newton {row['newton']}  rounds {row['rounds']}  "
            f"wall {row['wall [s]']:.1f} s  ETA {eta:.0f} s"
        )

    def _say(self, line: str, *, always: bool = False) -> None:
        """A line on the terminal (rank 0); ``quiet`` silences all but ``always``."""
        if (always or not self.quiet) and self.comm.rank == 0:
            print(line, file=sys.stdout, flush=True)
