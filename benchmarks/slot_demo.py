"""The collector bar slot demo's definitions (data, problem, nested iteration), not its runs."""

import sys
from pathlib import Path

DEMO = Path(__file__).resolve().parent.parent / "demos" / "demo_collector_bar_slot.py"


def slot_demo(*argv: str) -> dict:
    """The demo's namespace up to its runs, as if it were run with the arguments ``argv``."""
    sys.argv = [str(DEMO), *argv]
    namespace = {"__name__": "bench", "__file__": str(DEMO)}
    head = DEMO.read_text().split("runs: dict = {}")[0]
    exec(compile(head, str(DEMO), "exec"), namespace)
    return namespace
