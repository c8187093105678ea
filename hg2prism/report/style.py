"""What every world picture shares, whatever draws the world (the grid front end's drawer or
the arena graph): the hypothesis colours, the trap and trapped colours, step-number texts and
the legend entries of P2's hypotheses."""

from __future__ import annotations

from collections.abc import Sequence

import matplotlib.pyplot as plt

__all__ = ["HYPOTHESIS_COLOURS", "TRAP_COLOUR", "TRAPPED_COLOUR", "hypothesis_colour",
           "steps_text", "hypothesis_handles"]

HYPOTHESIS_COLOURS = ("tab:blue", "tab:orange", "tab:purple", "tab:brown", "tab:pink", "tab:olive")
TRAPPED_COLOUR = "red"
TRAP_COLOUR = "darkgreen"


def hypothesis_colour(x: int) -> str:
    return HYPOTHESIS_COLOURS[x % len(HYPOTHESIS_COLOURS)]


def steps_text(numbers: Sequence[int]) -> str:
    """Step numbers, shortened when many: "3,5,7" or "2…40 (20×)" (first, last, count)."""
    if len(numbers) <= 3:
        return ",".join(str(n) for n in numbers)
    return f"{numbers[0]}…{numbers[-1]} ({len(numbers)}×)"


def hypothesis_handles(hypotheses: Sequence[str], used: Sequence[int]) -> list:
    """Legend entries for the hypotheses P2 held along the drawn episode."""
    return [plt.Line2D([], [], color=hypothesis_colour(i), lw=2.2,
                       label=f"P2 believes x{i}: {hypotheses[i]}")
            for i in range(len(hypotheses)) if i in used]
