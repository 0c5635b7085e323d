"""A transient run stopped by a real signal resumes to the same end, step for step.

The demo ``demo_transient_joule.py --small`` runs under ``mpiexec -n 2`` as a subprocess (so
these tests run in the serial session only: an MPI job cannot start another from inside).
"""

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

ROOT = Path(__file__).parents[1]
DEMO = ROOT / "demos" / "demo_transient_joule.py"
MPIEXEC = Path(sys.executable).parent / "mpiexec"

pytestmark = pytest.mark.skipif(
    MPI.COMM_WORLD.size > 1, reason="starts its own mpiexec; run in the serial session"
)


def start(out: Path, ranks: int, *extra: str) -> subprocess.Popen:
    command = [sys.executable, str(DEMO), "--small", "--quiet", "--no-series", "--out", str(out)]
    command += extra
    if ranks > 1:
        command = [str(MPIEXEC), "-n", str(ranks), *command]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
    return subprocess.Popen(
        command,
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,  # its own process group: SIGKILL reaches every rank
    )


def finish(process: subprocess.Popen, expected: int = 0) -> str:
    output, _ = process.communicate(timeout=600)
    assert process.returncode == expected, output
    return output


def rows(out: Path) -> list[dict]:
    with open(out / "history.csv") as file:
        return list(csv.DictReader(file))


def interrupt(process: subprocess.Popen, out: Path, sig: int, after: int) -> None:
    """Send ``sig`` once the run has recorded ``after`` steps: SIGTERM to mpiexec (which
    passes it on to the ranks), SIGKILL to the whole process group (it cannot be passed on)."""
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and process.poll() is None:
        if (out / "history.csv").exists() and len(rows(out)) >= after:
            if sig == signal.SIGKILL:
                os.killpg(process.pid, sig)
            else:
                process.send_signal(sig)
            return
        time.sleep(0.05)
    raise AssertionError(f"the run ended or stalled before step {after}: {process.communicate()}")


def end_state(out: Path) -> dict[str, np.ndarray]:
    """Each body's end state from the run's latest checkpoint, by partition-free key."""
    folder = out / "checkpoints" / (out / "checkpoints" / "latest").read_text().strip()
    states = {}
    for path in sorted(folder.glob("body_*.npz")):
        with np.load(path) as data:
            states[path.stem] = (data["keys"], data["state"])
    return states


def assert_same_history(a: list[dict], b: list[dict], rtol: float) -> None:
    """The same steps, each once, in order, with the same times and probe values."""
    assert [r["step"] for r in b] == [str(i) for i in range(1, len(a) + 1)]
    assert [r["step"] for r in a] == [r["step"] for r in b]
    for x, y in zip(a, b, strict=True):
        for column in x:
            if column in ("wall [s]", "factorisations", "rounds", "newton"):
                continue  # the clock, and the restarted run factorises its bodies again
            if column == "heat imbalance [relative]":  # round-off itself: at most 1e-8
                assert max(float(x[column]), float(y[column])) < 1e-8
                continue
            u, v = float(x[column]), float(y[column])
            assert abs(u - v) <= rtol * max(abs(u), abs(v), 1e-300), (x["step"], column, u, v)


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "whole"
    finish(start(out, 2))
    return out


def test_sigterm_under_mpi_resumes_to_the_same_end_to_round_off(uninterrupted, tmp_path):
    """SIGTERM to mpiexec mid-run: every rank finishes its step, checkpoints, and stops; the
    restart on 2 ranks repeats the uninterrupted run's operations, so the end state and every
    row agree to round-off (measured: identical)."""
    out = tmp_path / "cut"
    process = start(out, 2)
    interrupt(process, out, signal.SIGTERM, after=4)
    said = finish(process, expected=1)
    assert "stopped by a signal" in said
    stopped = len(rows(out))
    assert 4 <= stopped < len(rows(uninterrupted))  # stopped mid-way
    said = finish(start(out, 2, "--restart"))
    assert f"step {stopped}" in said and "restarted from" in said
    # 1e-12: the same floating-point operations on the same partition give the same bits;
    # the margin covers only a different summation order should MPI reduce differently
    assert_same_history(rows(uninterrupted), rows(out), rtol=1e-12)
    whole, resumed = end_state(uninterrupted), end_state(out)
    for name, (keys, state) in whole.items():
        assert np.array_equal(keys, resumed[name][0])
        assert np.max(np.abs(state - resumed[name][1])) <= 1e-12 * np.max(np.abs(state))


def test_sigkill_resumes_from_the_last_checkpoint_on_another_rank_count(uninterrupted, tmp_path):
    """SIGKILL (no chance to save): the restart goes back to the last periodic checkpoint
    (every 5 steps), drops the rows recorded after it, and steps again from there, here on 1
    rank from a 2-rank checkpoint. Another partition changes the round-off of each Newton
    solve, so the runs agree to Newton's tolerance: rtol 1e-10 per field over a few hundred
    DOFs, carried through 30 steps of a damped (BDF2, diffusive) problem; 1e-7 leaves a
    margin of 10 for the error controller, which may choose a step differently when its
    estimate sits at the tolerance."""
    out = tmp_path / "killed"
    process = start(out, 2)
    interrupt(process, out, signal.SIGKILL, after=8)
    process.communicate(timeout=60)
    recorded = len(rows(out))
    said = finish(start(out, 1, "--restart"))
    assert "restarted from" in said
    resumed_at = int(said.split("step ")[1].split()[0])
    assert resumed_at % 5 == 0 and resumed_at <= recorded  # the last periodic checkpoint
    assert_same_history(rows(uninterrupted), rows(out), rtol=1e-7)
    whole, resumed = end_state(uninterrupted), end_state(out)
    for name, (keys, state) in whole.items():
        assert np.array_equal(keys, resumed[name][0])
        assert np.max(np.abs(state - resumed[name][1])) <= 1e-7 * np.max(np.abs(state))


def test_a_file_rewritten_when_the_run_is_killed_keeps_its_old_text(tmp_path, monkeypatch):
    """The history and the pointer to the latest checkpoint are rewritten at every step: a kill
    between writing the new text and renaming it into place (here: the rename raises) leaves
    the previous text whole. Truncating the file first left it empty, and the restart failed
    to read it (seen once in CI, a SIGKILL landing inside the write)."""
    from subdomain_contact.checkpoint import write_whole

    target = tmp_path / "history.json"
    write_whole(target, '{"rows": [1]}')

    def killed(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "replace", killed)
    with pytest.raises(KeyboardInterrupt):
        write_whole(target, '{"rows": [1, 2]}')
    assert target.read_text() == '{"rows": [1]}'
    monkeypatch.undo()
    write_whole(target, '{"rows": [1, 2]}')
    assert target.read_text() == '{"rows": [1, 2]}'
    assert sorted(p.name for p in tmp_path.iterdir()) == ["history.json"]
