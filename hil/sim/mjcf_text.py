"""How the generated MJCF writes a number (9 significant digits) and a vector of them: one rule for every
file that writes model text (``hil.sim.mjcf``, ``hil.sim.object_shapes``)."""

from __future__ import annotations

__all__ = ["num", "vec"]


def num(x: float) -> str:
    """A number as the model text writes it."""
    return f"{x:.9g}"


def vec(*xs: float) -> str:
    """Numbers separated by spaces, each as :func:`num` writes it."""
    return " ".join(num(x) for x in xs)
