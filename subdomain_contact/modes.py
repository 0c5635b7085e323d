"""A body's kernel modes: the constants of T and φ, the rigid motions of u.

They span what a body's matrix cannot see without its conditions: the coarse space of the
interface Krylov is made of them (on the masters), and so is the near-null space that
smoothed-aggregation AMG needs on a body solved iteratively (on the body's DOFs).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import numpy.typing as npt

__all__ = ["Mode", "modes"]

#: ``mode(field, component, x)``: the mode's values [K, V or m] at points ``x`` (n × 3, m).
Mode = Callable[[str, int | None, npt.NDArray[np.float64]], npt.NDArray[np.float64]]


def modes(fields: tuple[str, ...], dim: int) -> list[Mode]:
    """The kernel modes of a body with ``fields`` in ``dim`` dimensions.

    One constant per scalar field; for the displacement, ``dim`` translations and the
    rotations (1 in 2D, 3 in 3D) about the origin of ``x`` (centre the points first).
    """

    def constant(of: str) -> Mode:
        return lambda f, c, x: np.full(len(x), 1.0 if f == of else 0.0)

    def translation(d: int) -> Mode:
        return lambda f, c, x: np.full(len(x), 1.0 if f == "displacement" and c == d else 0.0)

    def rotation(a: int, b: int) -> Mode:  # in the plane of axes a, b: (−x_b, x_a)
        def mode(f, c, x):
            if f != "displacement":
                return np.zeros(len(x))
            return -x[:, b] if c == a else (x[:, a] if c == b else np.zeros(len(x)))

        return mode

    out = [constant(f) for f in fields if f != "displacement"]
    if "displacement" in fields:
        out += [translation(d) for d in range(dim)]
        planes = [(0, 1)] if dim == 2 else [(0, 1), (1, 2), (0, 2)]
        out += [rotation(a, b) for a, b in planes]
    return out
