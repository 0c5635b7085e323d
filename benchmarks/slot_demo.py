"""The collector bar slot demo's definitions (data, problem, nested iteration), not its runs."""

import argparse
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


def slot_parser(doc: str) -> argparse.ArgumentParser:
    """A benchmark's arguments: the slot's mesh sizes (the demo's default mesh, 65,900 DOFs)."""
    parser = argparse.ArgumentParser(description=doc)
    parser.add_argument(
        "--size", type=float, default=0.06, help="element size away from the slot [m]"
    )
    parser.add_argument("--fine", type=float, default=0.02, help="element size on the contacts [m]")
    return parser


def warm_slot(size: float, fine: float) -> tuple[dict, object]:
    """The demo's namespace and the slot's system (constant setup, bar of 160 mm) at a warm
    state (a uniform 1000 K: the contacts' laws away from their cold values), its Jacobian
    assembled."""
    demo = slot_demo("--size", str(size), "--fine", str(fine))
    system = demo["sc"].System(demo["problem"](demo["load"](0.16), "constant"))
    system.reset({"temperature": 1000.0})
    system.assemble_jacobian()
    return demo, system
