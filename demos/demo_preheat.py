# # Coke bed preheating of a Hall–Héroult cell: a 2D slice along one cathode block, in time
#
# Before a new cell is started, the line current is passed through a thin bed of coke grains
# laid between the anodes and the cathode blocks. The bed and its contacts heat by Joule effect
# until the cathode surface is hot enough to pour the bath; too fast or too uneven and the
# blocks crack. This demo follows that preheat from a cold cell to a stated end point (the
# mean cathode surface temperature reaching 900 °C, or a time limit) and reports what a preheat
# engineer reads: the cathode surface temperature (mean, min, max), the largest temperature
# gradient in the block, the cell voltage and power, where the power is dissipated (coke bed,
# its contacts, the carbon), and the energy balance of the whole run.
#
# ## The model
#
# `geo/preheat_slice.geo`: half a cell's width along one cathode block, from the centre line to
# the shell, through the collector bar's middle plane. Six bodies (anode, coke bed, cathode
# block, cast iron, collector bar, ramming paste), seven contacts, temperature T and potential
# φ in each (thermo-electric; with `--mechanics` the displacements too, quasi-static, plane
# strain in 2D: the contact pressures then follow the expansion of the parts; otherwise they
# are the loads stated below). A 2D slice of bodies of different widths out of its plane: each
# body's equations are those of its real width (the block's 0.48 m; the slot's 0.2 m for the
# cast iron, the bar's 0.16 m), i.e. its conductivities, heat capacity and stiffness are
# multiplied by that width, and each contact's conductances by the width it touches across
# (the slot's three faces, the bar's three faces), its normal stiffness by the width its
# in-plane force acts on (the slot's and the bar's top). Every integral is then the slice's
# own (W, A, N), and the current through the half slice is half a block's: 300 kA / 28 / 2.
# A slice is ill-suited to the mechanics (Richard et al., COM 2006, p. 16): the block stands
# on the cast iron (the slice passes through the slot), the slot's sides are out of its
# plane, and the cast iron's grip on the bar is missing; the 3D quarter has them.
#
# Materials and contact laws are data files under `data/` with their sources; the default
# schedule (`data/preheat_schedule.csv`) ramps the line current from 20 % to 100 % in 24 h,
# then holds it. Boundary conditions, this model's choices (documented in `report.json`):
# convection to 323 K through the cover above the anodes, the lining below, the ramming
# paste's side and top and the bar out of the shell; the centre line is a symmetry plane;
# φ = 0 at the bar's end; the current enters the anodes through their stubs.
#
# Run `python demos/demo_preheat.py` (`--small`: a coarse mesh and the first hours, for the
# tests; `--quarter`: the 3D quarter of the slice, `geo/preheat_quarter.geo`, with its real
# widths; `--coke 0.03`: a thicker bed; `--restart`: go on from the latest checkpoint;
# `--no-study`: the base case only, not the 30 mm bed; `--size`, `--fine`: the mesh;
# `--mechanics`: the displacements too, and the contact pressures and openings in the report).

import argparse
import csv
import json
import time
from dataclasses import replace
from pathlib import Path

import dolfinx_solver  # noqa: F401  (before dolfinx and petsc4py)

# isort: split
import dolfinx
import matplotlib
import ufl
from mpi4py import MPI

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import subdomain_contact as sc
from subdomain_contact.newton import FORCING, STEP_RTOL
from subdomain_contact.physics import (
    Convection,
    CurrentDensity,
    Displacement,
    Potential,
    Problem,
)

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "data"
HOUR = 3600.0
parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--small", action="store_true", help="a coarse mesh and the first hours")
parser.add_argument("--out", type=Path, default=Path("out_preheat"))
parser.add_argument("--quiet", action="store_true", help="no progress line")
parser.add_argument("--restart", action="store_true", help="go on from the latest checkpoint")
parser.add_argument("--coke", type=float, default=0.02, help="coke bed thickness [m]")
parser.add_argument(
    "--schedule", type=Path, default=DATA / "preheat_schedule.csv", help="line current CSV"
)
parser.add_argument("--target", type=float, default=1173.15, help="end point: mean T [K]")
parser.add_argument("--hours", type=float, help="time limit [h] (default 120; --small 6)")
parser.add_argument("--tolerance", type=float, default=2.0, help="local error per step [K]")
parser.add_argument("--no-study", action="store_true", help="the base case only")
parser.add_argument("--size", type=float, help="element size away from the contacts [m]")
parser.add_argument("--fine", type=float, help="element size on the contacts [m]")
parser.add_argument(
    "--quarter", action="store_true", help="the 3D quarter (geo/preheat_quarter.geo)"
)
parser.add_argument(
    "--mechanics", action="store_true", help="the displacements too: contact pressures"
)
parser.add_argument(
    "--slot-law",
    choices=("constant", "pressure"),
    default="constant",
    help="cast iron/carbon: the constant resistances of slot models, or the law of p and T "
    "(the 3D quarter with --mechanics)",
)
args = parser.parse_args()
if args.slot_law == "pressure" and not (args.quarter and args.mechanics):
    parser.error("--slot-law pressure needs --quarter --mechanics (the pressure on the slot)")
comm = MPI.COMM_WORLD
started = time.perf_counter()


def say(*text: object) -> None:
    if comm.rank == 0 and not args.quiet:
        print(*text, flush=True)


if args.quarter:
    size, fine = (0.2, 0.04) if args.small else (0.12, 0.03)
else:
    size, fine = (0.16, 0.04) if args.small else (0.04, 0.01)
size, fine = args.size or size, args.fine or fine
limit = HOUR * (args.hours or (6.0 if args.small else 120.0))

# ## Data
#
# 300 kA line current, 28 cathode blocks (Dupuis 2011, as the slot scene): the half slice
# carries half a block's current at full line current, the quarter half of that.
LINE_CURRENT = 300e3  # A
SLICE_CURRENT = LINE_CURRENT / 28 / (4 if args.quarter else 2)  # A
BLOCK_WIDTH = 0.48  # m, out of the slice's plane (Dupuis 2011)
WIDTH = {  # m: each body's width out of the plane (the 3D quarter has its real widths)
    "anode": BLOCK_WIDTH,  # the slice cuts a block-wide strip of the anodes above
    "coke": BLOCK_WIDTH,
    "block": BLOCK_WIDTH,
    "cast_iron": 0.2,  # the slot's mean width (Dupuis 2011)
    "bar": 0.16,  # the bar (Dupuis 2011)
    "paste": BLOCK_WIDTH,
}
if args.quarter:
    WIDTH = dict.fromkeys(WIDTH, 1.0)
    BLOCK_WIDTH = 1.0
SLOT_H, BAR = 0.176, 0.16  # m
# the anode top under the stubs: m (2D: 3 of 0.18 m) or m² (3D: 3 half stubs of 0.18 × 0.09)
STUBS = 3 * 0.18 * (0.09 if args.quarter else 1.0)
AMBIENT = 323.15  # K (this model's choice, as the slot scene)
START = AMBIENT  # K, the cold cell
LOSSES = {  # W/(m² K) of real surface: this model's choices, see the report
    "anode_cover": 3.0,  # 0.1 m of alumina/crushed bath cover, k ≈ 0.3 W/(m K)
    "anode_sides": 3.0,  # the channels, covered as the anodes' tops
    "coke_sides": 3.0,
    "block_top": 3.0,  # the block between and beyond the anodes, under the cover
    "bottom": 2.0,  # the lining: 0.4 m of refractory and insulation, k ≈ 0.8 W/(m K)
    "paste_top": 3.0,  # the side ledge, covered
    "sidewall": 5.0,  # side lining and shell
    "bar_surface": 10.0,  # the bar through the lining and the shell
    "bar_end": 50.0,  # the bar's end, to the flexible and the busbar
}
LOSS_BODY = {  # the body each loss group belongs to (for its width)
    "anode_cover": "anode",
    "anode_sides": "anode",
    "coke_sides": "coke",
    "block_top": "block",
    "bottom": "bar",
    "paste_top": "paste",
    "sidewall": "paste",
    "bar_surface": "bar",
    "bar_end": "bar",
}
ANODE_PRESSURE = 1560.0 * 9.81 * 0.6  # Pa: an anode's weight on the bed, ρ g h (9.2 kPa)
SLIP = 1e7  # Pa/m: the spring against slip of every contact (--mechanics; as the slot scene)


def widened(value, width: float, pressed: float = 1.0):
    """A property (number or law (p, T)) of a slice of ``width`` [m] out of the plane.

    ``pressed`` [m]: the width whose force a contact's pressure in the slice carries (the
    slice's pressure is ``pressed`` times the real one, which the law is given).
    """
    if callable(value):
        return lambda p, T: width * value(p / pressed, T)
    return width * float(value)


def material(path: Path, width: float, stress_free: float | None = None) -> sc.Material:
    """A data file's material, for a body ``width`` [m] wide (its mechanics: --mechanics).

    ``stress_free`` [K]: its temperature of zero thermal strain, default the file's.
    """
    fields = "TEu" if args.mechanics else "TE"
    m = sc.load_material(path, fields=fields, stress_free_temperature=stress_free)
    return replace(
        m,
        conductivity=widened(m.conductivity, width),
        electrical_conductivity=widened(m.electrical_conductivity, width),
        density=width * m.density,
        young=None if m.young is None else widened(m.young, width),
    )


def contact(
    path: Path,
    width: float,
    pressure: float = 0.0,
    pressed: float | None = None,
    stated: bool = False,
) -> sc.Contact:
    """A contact of a data file, across ``width`` [m].

    Without the mechanics, its laws at the stated ``pressure`` [Pa]; with it, unilateral, its
    slip held by a weak spring, its normal force carried by ``pressed`` [m] of the width
    (default all of it; in 2D the bar's sides conduct but lie in the slice's plane), its laws
    at the pressure computed (``stated``: still at the stated one).
    """
    c = sc.load_contact(path)
    pressed = width if pressed is None else pressed
    computed = args.mechanics and not stated  # the laws see the slice's pressure
    laws = {
        name: widened(getattr(c, name), width, pressed if computed else 1.0)
        for name in ("conductance", "electrical_conductance")
    }
    if not args.mechanics:  # the laws see Contact.pressure
        return replace(c, **laws, normal=None, pressure=pressure)
    if stated:  # a displacement field, but laws held at the stated pressure
        laws = {name: at_pressure(law, pressure) for name, law in laws.items()}
    return replace(
        c,
        **laws,
        normal=sc.Penalty(pressed * c.normal.stiffness),
        tangential="stuck",
        slip_stiffness=pressed * SLIP,
    )


def at_pressure(law, pressure: float):
    """A law (p, T) evaluated at the stated ``pressure`` [Pa], whatever the contact's."""
    if not callable(law):
        return law
    return lambda p, T: law(pressure, T)


def slot_contact() -> sc.Contact:
    """Cast iron / carbon over the slot's three faces: two sides (4 µΩ m²) and the top (8).

    With the mechanics, the top's pressure is the slice's; the sides, out of its plane, are
    given the top's (their laws here do not depend on it).
    """
    folder = DATA / "contacts"
    side = sc.load_contact(folder / "carbon_cast_iron_vertical_constant.toml")
    top = sc.load_contact(folder / "carbon_cast_iron_horizontal_constant.toml")
    sides, across = 2 * SLOT_H, WIDTH["cast_iron"]  # m of slot face per m of slot
    pressed = across if args.mechanics else 1.0

    def both(a, b):
        a, b = sc.laws.as_law(a), sc.laws.as_law(b)
        return lambda p, T: sides * a(p / pressed, T) + across * b(p / pressed, T)

    laws = {
        "conductance": both(side.conductance, top.conductance),
        "electrical_conductance": both(side.electrical_conductance, top.electrical_conductance),
    }
    if not args.mechanics:
        return sc.Contact(**laws)
    return sc.Contact(
        **laws,
        normal=sc.Penalty(across * top.normal.stiffness),
        tangential="stuck",
        slip_stiffness=across * SLIP,
    )


BODIES = ["anode", "coke", "block", "cast_iron", "bar", "paste"]
INTERFACES = ["anode_coke", "coke_block", "slot_top", "bar_top"]
INTERFACES += ["slot_side", "bar_side"] if args.quarter else []  # 2D: in the top faces
INTERFACES += ["block_paste", "iron_paste", "bar_paste"]
BAR_PRESSURE = 0.1e6  # Pa: the bar/cast iron contact's pressure, this model's assumption


def schedule(path: Path) -> sc.Schedule:
    """The line current's share against time, from the CSV (hours, share)."""
    with path.open() as f:
        rows = [r for r in csv.reader(line for line in f if not line.startswith("#"))][1:]
    hours, share = np.array(rows, dtype=float).T
    return sc.Schedule(tuple(hours * HOUR), tuple(share * SLICE_CURRENT / STUBS))


def problem(scene: sc.Scene, current: sc.Schedule) -> Problem:
    folder, contacts_ = DATA / "materials", DATA / "contacts"
    files = {
        "anode": "anode_carbon",
        "coke": "coke_bed",
        "block": "graphite_at101",  # the graphitized block's stand-in (see the file)
        "cast_iron": "grey_cast_iron",
        "bar": "collector_bar_steel",
        "paste": "ramming_paste",
    }
    materials = {
        b: material(folder / f"{f}.toml", WIDTH[b], STRESS_FREE.get(b)) for b, f in files.items()
    }
    bed = contacts_ / "coke_bed_carbon.toml"
    paste = contacts_ / "ramming_paste_bonded.toml"
    contacts = {
        "anode_coke": contact(bed, BLOCK_WIDTH, ANODE_PRESSURE),
        "coke_block": contact(bed, BLOCK_WIDTH, ANODE_PRESSURE),
        "block_paste": contact(paste, BLOCK_WIDTH),
        "iron_paste": contact(paste, WIDTH["cast_iron"]),
    }
    bar = contacts_ / "steel_cast_iron.toml"  # at an assumed pressure
    if args.quarter:  # each face on its own
        if args.slot_law == "pressure":  # open where the pressure vanishes
            law = contacts_ / "carbon_cast_iron_pressure.toml"
            contacts["slot_side"] = contacts["slot_top"] = contact(law, 1.0)
        else:
            side = contacts_ / "carbon_cast_iron_vertical_constant.toml"
            contacts["slot_side"] = contact(side, 1.0)
            top = contacts_ / "carbon_cast_iron_horizontal_constant.toml"
            contacts["slot_top"] = contact(top, 1.0)
        contacts["bar_side"] = contacts["bar_top"] = contact(bar, 1.0, BAR_PRESSURE)
        contacts["bar_paste"] = contact(paste, 1.0)
    else:  # the slot's three faces in one, the bar's three faces in one
        contacts["slot_top"] = slot_contact()
        # the cast iron's grip on the bar is out of the slice: its conductance stays at
        # the stated pressure
        bar_top = contact(bar, 3 * BAR, BAR_PRESSURE, pressed=PRESSED["bar_top"], stated=True)
        contacts["bar_top"] = bar_top
        contacts["bar_paste"] = contact(paste, 3 * BAR, pressed=BAR)
    conditions = [CurrentDensity("stubs", current), Potential("bar_end", 0.0)] + [
        Convection(g, h * WIDTH[LOSS_BODY[g]], AMBIENT) for g, h in LOSSES.items()
    ]
    if args.mechanics:
        conditions += SUPPORTS
    return Problem(scene, materials, contacts, conditions)


# The mechanics' supports (--mechanics), this model's choices: the centre line (and in 3D the
# bar's middle plane and the plane between two blocks) are symmetry planes; the bar and the
# block stand on the lining (2D: the bar alone, the slice passing through the slot); the
# anodes' weight rests on the bed (a pressure on their top); the shell gives way (the ramming
# paste's outer face is free). Every contact is stuck, its slip held by the weak spring SLIP.
UP = 2 if args.quarter else 1
# The cast iron is stress-free at its eutectic (its data file): cooled to the cold cell, it
# grips the bar and leaves the slot's faces open. The 2D slice has no grip (the bar's sides are
# out of its plane), and there the cast iron is taken stress-free at the start temperature.
STRESS_FREE = {} if args.quarter else {"cast_iron": START}
SUPPORTS = [
    Displacement("symmetry", 0, 0.0),
    Displacement("bottom", UP, 0.0),
    sc.Pressure("stubs", ANODE_PRESSURE * BLOCK_WIDTH),
    sc.Pressure("anode_cover", ANODE_PRESSURE * BLOCK_WIDTH),
]
if args.quarter:
    SUPPORTS += [Displacement("symmetry_y", 1, 0.0), Displacement("block_side", 1, 0.0)]
# the width [m] that carries each contact's normal force in the slice (its pressure there is
# that width times the real one); the quarter has its real widths
PRESSED = {
    "anode_coke": BLOCK_WIDTH,
    "coke_block": BLOCK_WIDTH,
    "slot_top": WIDTH["cast_iron"],
    "bar_top": 1.0 if args.quarter else BAR,
    "slot_side": 1.0,
    "bar_side": 1.0,
}


def load(coke: float) -> sc.Scene:
    return sc.load_scene(
        ROOT / "geo" / ("preheat_quarter.geo" if args.quarter else "preheat_slice.geo"),
        bodies=BODIES,
        interfaces=INTERFACES,
        parameters={"size": size, "fine": fine, "coke": coke},
    )


# ## What is read at every step
class Probes:
    """The cathode surface, the block's gradient, the voltage, the power and where it goes."""

    def __init__(self, system: sc.System) -> None:
        self.system = system
        block = system.bodies.get("block")
        self.gradient = None
        if block is not None:
            V, parent = block.forms.collapsed("temperature")
            self.T = dolfinx.fem.Function(V)
            self.parent = parent
            Q = dolfinx.fem.functionspace(V.mesh, ("DG", 0))
            self.g = dolfinx.fem.Function(Q)
            grad = ufl.grad(self.T)
            self.gradient = dolfinx.fem.Expression(
                ufl.sqrt(ufl.inner(grad, grad)), Q.element.interpolation_points
            )
            # the block's top face (the cathode surface): ∫ T and its area [m or m²]
            mesh, top = V.mesh, V.mesh.topology.dim - 1
            facets = dolfinx.mesh.locate_entities_boundary(
                mesh, top, lambda x: np.isclose(x[top], 0.48)
            )
            tags = dolfinx.mesh.meshtags(mesh, top, facets, np.ones_like(facets))
            ds = ufl.Measure("ds", domain=mesh, subdomain_data=tags, subdomain_id=1)
            one = dolfinx.fem.Constant(mesh, 1.0)
            self.top = [dolfinx.fem.form(self.T * ds), dolfinx.fem.form(one * ds)]

    def surface(self) -> tuple[float, np.ndarray, np.ndarray]:
        """Mean T [K] of the cathode surface; x [m] and T [K] of its nodes, on every rank."""
        x, T, integrals = np.zeros(0), np.zeros(0), np.zeros(2)
        block = self.system.bodies.get("block")
        if block is not None:
            self.T.x.array[:] = block.U.x.array[self.parent]
            integrals = np.array([dolfinx.fem.assemble_scalar(f) for f in self.top])
            xyz, values = block.nodal("temperature")
            on = np.isclose(xyz[:, block.forms.W.mesh.topology.dim - 1], 0.48)
            x, T = xyz[on, 0], values[on]
        integrals = comm.allreduce(integrals, op=MPI.SUM)  # each facet on one rank
        x, T = (np.concatenate(comm.allgather(a)) for a in (x, T))
        return float(integrals[0] / integrals[1]), x, T

    def largest_gradient(self) -> float:
        """max |∇T| in the block [K/m]."""
        local = 0.0
        if self.gradient is not None:
            block = self.system.bodies["block"]
            self.T.x.array[:] = block.U.x.array[self.parent]
            self.g.interpolate(self.gradient)
            local = float(np.max(self.g.x.array, initial=0.0))
        return comm.allreduce(local, op=MPI.MAX)

    def __call__(self, system: sc.System) -> dict[str, float]:
        report = sc.summary(system)
        bulk = sc.bulk_heat(system)
        contact_joule = {k: c["Joule heat"] for k, c in report["contacts"].items()}
        mean, x, T = self.surface()
        current = report["groups"]["stubs"]["current"]
        voltage = report["groups"]["stubs"]["potential"]
        heat = report["balance"]["heat"]
        generated = heat["generated"]  # the bulk's and the contacts' Joule heat
        lost = -sum(group["heat"] for group in report["groups"].values() if "heat" in group)
        pressures = {}  # the real ones (see PRESSED) [MPa]
        if args.mechanics:
            for k, width in PRESSED.items():
                if k in report["contacts"]:
                    row = report["contacts"][k]
                    pressures[f"{k} mean pressure [MPa]"] = 1e-6 * row["mean pressure"] / width
                    pressures[f"{k} max pressure [MPa]"] = 1e-6 * row["max pressure"] / width
                    pressures[f"{k} open share"] = row["open share"]
            pressures["force imbalance [relative]"] = report["balance"]["force"]["relative"]
        # the block's current leaves through the slot's faces or the ramming paste
        slot = sum(abs(c["current"]) for k, c in report["contacts"].items() if "slot" in k)
        return pressures | {
            "line current [kA]": 1e-3 * current * LINE_CURRENT / SLICE_CURRENT,
            "slot faces current share": slot / current,
            "ramming paste current share": abs(report["contacts"]["block_paste"]["current"])
            / current,
            "cathode surface mean T [K]": mean,
            "cathode surface min T [K]": float(T.min()),
            "cathode surface max T [K]": float(T.max()),
            "coldest point x [m]": float(x[np.argmin(T)]),
            "hottest point x [m]": float(x[np.argmax(T)]),
            "largest gradient in the block [K/m]": self.largest_gradient(),
            "voltage [V]": voltage,
            "power [W]": voltage * current,
            "coke bed share": bulk["coke"] / generated,
            "coke contacts share": (contact_joule["anode_coke"] + contact_joule["coke_block"])
            / generated,
            "carbon share": (bulk["anode"] + bulk["block"] + bulk["paste"]) / generated,
            "generated [W]": generated,
            "lost [W]": lost,
            "stored [W]": heat["stored"],
            "heat imbalance [relative]": heat["relative"],
        }


def route(name: str):
    """Newton's linear solver: ``"subdomain"`` or ``"monolithic"``."""
    return sc.Subdomains() if name == "subdomain" else sc.Monolithic()


def run(coke: float, out: Path, linear: str = "subdomain", restart: bool = False) -> dict:
    """The preheat of a ``coke`` [m] bed from the cold cell to the end point.

    ``linear``: Newton's linear solver, ``"subdomain"`` or ``"monolithic"``.
    """
    current = schedule(args.schedule)
    system = sc.System(problem(load(coke), current))
    system.reset({"temperature": START})
    cold = sc.enthalpy(system)  # [J]
    stepper = sc.Stepper(system, "bdf2")
    probes = Probes(system)
    history = sc.History(
        out, stepper, probes, until=limit, vtk_every=20, checkpoint_every=5, quiet=args.quiet
    )
    resumed = history.start(restart=restart)
    say(f"{coke * 1e3:.0f} mm bed, {linear}: {system.num_dofs()} DOFs on {comm.size} rank(s)")
    reached = []

    def after_step(stepper: sc.Stepper, result) -> bool:
        stop = history.after_step(stepper, result)
        if history.rows and history.rows[-1]["cathode surface mean T [K]"] >= args.target:
            reached.append(stepper.time)
            return True
        return stop

    solver = route(linear)
    tic = time.perf_counter()
    stepper.march(
        limit,
        600.0,
        tolerance=args.tolerance,
        max_step=2 * HOUR,
        after_step=after_step,
        linear=solver,
        rtol=1e-10,
    )
    solver.destroy()
    history.finish()
    seconds = time.perf_counter() - tic
    rows = history.rows
    times = np.array([r["time [s]"] for r in rows])
    steps = np.array([r["step [s]"] for r in rows])

    # Energy over the run [J]. Each step's equation holds its own balance, to Newton's
    # tolerance: electrical power in (V I) = Joule heat = lost + stored at the step's end, the
    # stored heat being ρ c_p(Tⁿ) times BDF2's rate; their sums times the steps ("scheme")
    # close to that tolerance. The heat stored in fact is the change of the bodies' enthalpy
    # (sc.enthalpy, exact in T): against the electrical energy in minus the heat lost, both
    # integrated in time by the trapezoidal rule (second order, as BDF2), it gives the energy
    # balance of the run, whose error is the time integration's.
    def integral(key: str, rule: str) -> float:
        values = np.array([r[f"{key} [W]"] for r in rows])
        if rule == "scheme":
            return float(np.sum(steps * values))
        start = values[0]  # t = 0: the first step's value (its 600 s are a small share)
        return float(np.trapezoid(np.concatenate([[start], values]), np.r_[0.0, times]))

    energy = {
        "scheme": {k: integral(k, "scheme") for k in ("power", "generated", "lost", "stored")},
        "electrical in": integral("power", "trapezoid"),
        "lost": integral("lost", "trapezoid"),
        "enthalpy change": sc.enthalpy(system) - cold,
    }
    scheme = energy["scheme"]
    scheme["imbalance"] = scheme["generated"] - scheme["lost"] - scheme["stored"]
    energy["imbalance"] = energy["electrical in"] - energy["lost"] - energy["enthalpy change"]
    energy["imbalance, relative"] = energy["imbalance"] / energy["electrical in"]
    out_report = {
        "coke [m]": coke,
        "linear": linear,
        "dofs": system.num_dofs(),
        "steps": stepper.steps,
        "rejected": stepper.rejected,
        "resumed": resumed,
        "end point reached [h]": reached[0] / HOUR if reached else None,
        "end time [h]": float(times[-1] / HOUR) if len(times) else 0.0,
        "peak gradient [K/m]": max(r["largest gradient in the block [K/m]"] for r in rows),
        "max heat imbalance": max(r["heat imbalance [relative]"] for r in rows),
        "energy [J]": energy,
        "factorisations": int(sum(r["factorisations"] for r in rows)),
        "newton": [r["newton"] for r in rows],
        "seconds": seconds,
        "end": rows[-1],
    }
    system.destroy()
    return out_report


# ## Subdomain and monolithic Newton, step by step (the first steps, fixed length)
#
# Newton stops where each field's residual is below 1e-10 of its scale, which bounds a
# state's error by the residual over the stiffness that holds it. With the mechanics, the
# bar, its cast iron and the paste are held along the slot by the slip spring and the open
# contacts' ties alone, about 1e-6 of the scale's stiffness (inferred from the run below: a
# residual of 2.4e-12 left them 1.5e-6 off), so a route's state may be up to 1e-4 off there
# by that test. Measured (2 ranks, 2026-12-08, a machine with AVX-512 kernels): the first
# step's subdomain Newton stopped at a residual of 2.4e-12 of the scale after a step of
# 9.2e-4, 1.5e-6 of the largest displacement away from the monolithic one's, which took a
# step more (9.3e-11 apart elsewhere, where the paths end alike). So each route's state is
# compared after more Newton steps, applied, until one moves every field by at most
# `STEP_RTOL` (1e-9) of its largest value, Newton's own step test: the first correction is
# that route's error estimate (reported). There the corrections fell by a factor of about
# 1.6e-3 a step on both routes (1.5e-6, 2.4e-9, 3.9e-12 on the subdomain route's first
# step; 2.2e-9, 3.5e-12 on the monolithic one's): linear convergence, as the Newton matrix
# holds open contacts by a tie that the residual has not (physics._half_link: "exact to
# 1e-3 on open nodes"; a finite difference along the correction matched the matrix's
# product to 1.59e-3 at two amplitudes 10 apart), so a last correction c leaves about
# 1.6e-3 c, 2e-12 at most. The routes then agree to 8e-16.
POLISH_STEPS = 3  # at most: 1.5e-6, 2.4e-9, then below STEP_RTOL


def polish(system: sc.System, linear) -> dict[str, float]:
    """One more Newton step from the system's state, applied (collective).

    Returns: Each field's correction, relative to the field's largest value: Newton's
    estimate of the error of the state before it.
    """
    x, f = system.state(), system.create_vector()
    system.residual(f)
    system.assemble_jacobian()
    linear.setup(system)
    # to Newton's own forcing term: the correction to 1e-8 of itself
    f.array[:] = linear.solve(f.array_r.copy(), sc.Tolerance(rtol=FORCING))[0]
    sizes, step = system.field_max_norms(x), system.field_max_norms(f)
    x.axpy(-1.0, f)
    system.set_state(x)
    x.destroy()
    f.destroy()
    return {n: step[n] / sizes[n] if sizes[n] > 0 else step[n] for n in step}


def routes(coke: float, steps: int, length: float) -> dict:
    """At each of ``steps`` steps: each route's error estimate (its first :func:`polish`),
    and the largest per-field difference between the two routes, each polished until a
    correction is at most ``STEP_RTOL`` (at most :data:`POLISH_STEPS`)."""
    current = schedule(args.schedule)
    scene = load(coke)
    systems = {name: sc.System(problem(scene, current)) for name in ("subdomain", "monolithic")}
    steppers, solvers = {}, {name: route(name) for name in systems}
    for name, system in systems.items():
        system.reset({"temperature": START})
        steppers[name] = sc.Stepper(system, "bdf2")
    differences, seconds = [], dict.fromkeys(systems, 0.0)
    estimates: dict[str, list] = {name: [] for name in systems}
    polished: dict[str, list] = {name: [] for name in systems}  # the last corrections
    for _ in range(steps):
        for name, stepper in steppers.items():
            tic = time.perf_counter()
            stepper.advance(length, solvers[name], rtol=1e-10)
            seconds[name] += time.perf_counter() - tic
            correction = polish(systems[name], solvers[name])
            estimates[name].append(correction)
            for _ in range(POLISH_STEPS - 1):
                if max(correction.values()) <= STEP_RTOL:
                    break
                correction = polish(systems[name], solvers[name])
            polished[name].append(correction)
        a, b = (s.state() for s in systems.values())
        differences.append(systems["subdomain"].difference(a, b))
        a.destroy()
        b.destroy()
    for solver in solvers.values():
        solver.destroy()
    for system in systems.values():
        system.destroy()
    return {
        "step [s]": length,
        "differences": differences,
        "newton error estimates": estimates,
        "last corrections": polished,
        "seconds": seconds,
    }


args.out.mkdir(parents=True, exist_ok=True)
report: dict = {
    "model": {
        "slice current at full line current [A]": SLICE_CURRENT,
        "widths [m]": WIDTH,
        "losses [W/(m2 K)]": LOSSES,
        "ambient [K]": AMBIENT,
        "start [K]": START,
        "anode pressure on the bed [Pa]": ANODE_PRESSURE,
        "bar/cast iron pressure [Pa]": "computed" if args.mechanics else BAR_PRESSURE,
        "mechanics": {
            "supports": [str(bc) for bc in SUPPORTS],
            "slip spring [Pa/m]": SLIP,
            "stress-free temperatures": "each material file's (cast iron: its eutectic)",
        }
        if args.mechanics
        else None,
        "end point": f"mean cathode surface temperature {args.target} K, or {limit / HOUR} h",
        "schedule": str(args.schedule),
    },
    "ranks": comm.size,
}
report["routes"] = routes(args.coke, 3, 600.0)
say(f"routes: largest differences per step {report['routes']['differences']}, Newton's "
    f"error estimates {report['routes']['newton error estimates']}")  # fmt: skip
# The base bed by both routes (--small: the subdomain route; the routes are compared above),
# then the 30 mm bed by the subdomain route.
cases = [(args.coke, "subdomain")]
cases += [] if args.small else [(args.coke, "monolithic")]
cases += [] if args.no_study or args.small else [(0.03, "subdomain")]
report["runs"] = {}
for coke, linear in cases:
    key = f"coke {coke * 1e3:.0f} mm" + ("" if linear == "subdomain" else f", {linear}")
    folder = args.out / key.replace(" ", "_").replace(",", "")
    report["runs"][key] = run(coke, folder, linear, restart=args.restart)
    r = report["runs"][key]
    say(
        f"{key}: {r['steps']} steps to {r['end time [h]']:.1f} h in {r['seconds']:.0f} s, "
        f"end point {r['end point reached [h]']}, peak gradient {r['peak gradient [K/m]']:.0f} "
        f"K/m, energy balance of the run (time integration) "
        f"{r['energy [J]']['imbalance, relative']:.1e}"
    )
    report["runs"][key]["folder"] = folder.name
# What the preheat engineer compares: time to the end point and peak gradient per bed; and
# what the solver user compares: each route's time and factorisations on the same run.
report["comparison"] = {
    key: {
        "end point reached [h]": r["end point reached [h]"],
        "peak gradient [K/m]": r["peak gradient [K/m]"],
        "surface spread at the end [K]": r["end"]["cathode surface max T [K]"]
        - r["end"]["cathode surface min T [K]"],
    }
    for key, r in report["runs"].items()
    if r["linear"] == "subdomain"
}
routes_run = [r for r in report["runs"].values() if r["coke [m]"] == args.coke]
if len(routes_run) == 2:
    sub, mono = routes_run
    report["subdomain / monolithic"] = {
        "seconds": [sub["seconds"], mono["seconds"], sub["seconds"] / mono["seconds"]],
        "factorisations": [sub["factorisations"], mono["factorisations"]],
        "steps": [sub["steps"], mono["steps"]],
    }
    say(f"subdomain / monolithic: {report['subdomain / monolithic']}")
report["seconds"] = time.perf_counter() - started
if comm.rank == 0:
    (args.out / "report.json").write_text(json.dumps(report, indent=1, default=float))
    rows_of_plots = 3 if args.mechanics else 2
    figure, axes = plt.subplots(rows_of_plots, 2, figsize=(12, 4 * rows_of_plots))
    for key, r in report["runs"].items():
        if r["linear"] != "subdomain":
            continue  # the same curves
        with (args.out / r["folder"] / "history.json").open() as f:
            rows = json.load(f)["rows"]
        t = np.array([row["time [s]"] for row in rows]) / HOUR

        def col(name, rows=rows):
            return np.array([row[name] for row in rows])

        ax = axes[0, 0]
        for part in ("mean", "min", "max"):
            ax.plot(t, col(f"cathode surface {part} T [K]") - 273.15, label=f"{key}, {part}")
        ax.set_ylabel("cathode surface T [°C]")
        axes[0, 1].plot(t, col("largest gradient in the block [K/m]"), label=key)
        axes[0, 1].set_ylabel("largest |∇T| in the block [K/m]")
        axes[1, 0].plot(t, col("voltage [V]"), label=f"{key}, voltage")
        axes[1, 0].set_ylabel("voltage stubs to bar end [V]")
        for part in ("coke bed", "coke contacts", "carbon"):
            axes[1, 1].plot(t, col(f"{part} share"), label=f"{key}, {part}")
        axes[1, 1].set_ylabel("share of the Joule heat")
        if args.mechanics:
            for k in PRESSED:
                if f"{k} mean pressure [MPa]" in rows[0]:
                    axes[2, 0].plot(t, col(f"{k} mean pressure [MPa]"), label=f"{key}, {k}")
                    axes[2, 1].plot(t, col(f"{k} open share"), label=f"{key}, {k}")
            axes[2, 0].set_ylabel("mean contact pressure [MPa]")
            axes[2, 0].set_yscale("symlog", linthresh=1e-3)
            axes[2, 1].set_ylabel("share of the contact open")
    for ax in axes.flat:
        ax.set_xlabel("time [h]")
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    figure.suptitle(
        "coke bed preheat, " + ("3D quarter" if args.quarter else "2D slice along a cathode block")
    )
    figure.tight_layout()
    figure.savefig(args.out / "preheat.png", dpi=110)
    plt.close(figure)
say(f"wrote {args.out}/ in {time.perf_counter() - started:.1f} s")
