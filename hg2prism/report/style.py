"""What every world picture shares, whatever draws the world (the grid front end's drawer or
the arena graph): the hypothesis colours, the trap and trapped colours, step-number texts, the
step-numbering rule every figure states, the legend entries of P2's hypotheses, and the label
placer (`Placer`): each label goes to the first of a list of candidate spots where its box
overlaps no box taken before it (texts, marks)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import matplotlib.pyplot as plt
import numpy as np

__all__ = ["HYPOTHESIS_COLOURS", "TRAP_COLOUR", "TRAPPED_COLOUR", "STEP_RULE", "hypothesis_colour",
           "steps_text", "hypothesis_handles", "change_handle", "Box", "Placer"]

# The one step-numbering rule of the world picture, the belief plot and the replay
# (docs/semantics.md §15 "Figures"), in the short form the figures print.
STEP_RULE = ("step n = P1's n-th move; P2's hypothesis at step n = hers after observing "
             "step n")

# One colour per hypothesis, none the traps' green or the trapped red; twelve, so that with
# the belief figure's four dashes and six markers no two of the first twelve hypotheses look
# alike (with six colours x5 and x11 had one colour, dash and marker).
HYPOTHESIS_COLOURS = ("tab:blue", "tab:orange", "tab:purple", "tab:brown", "tab:pink", "tab:olive",
                      "tab:cyan", "tab:gray", "navy", "goldenrod", "teal", "magenta")
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


def change_handle() -> plt.Line2D:
    """The key's entry for the bold labels "n=k: P2 now x" of a world picture. An arrow's
    colour is the hypothesis P2 held during its step, a bold label her hypothesis after
    observing it: on world3 step 2's arrow is blue beside "n=2: P2 now x1" in orange, which the
    key did not explain (a figure review)."""
    return plt.Line2D([], [], color="0.2", ls="", marker=r"$\mathbf{x}$", ms=8,
                      label="n=k: P2 now x (bold): her change of mind\non observing step k")


Box = tuple[float, float, float, float]      # x0, y0, x1, y1 in data units


def _overlap(box: Box, boxes: np.ndarray) -> float:
    across = np.minimum(box[2], boxes[:, 2]) - np.maximum(box[0], boxes[:, 0])
    up = np.minimum(box[3], boxes[:, 3]) - np.maximum(box[1], boxes[:, 1])
    return float(np.sum(np.clip(across, 0, None) * np.clip(up, 0, None)))


@dataclass
class Placer:
    """Places texts on the first free candidate spot of an axes laid out for good (module
    docstring). `taken` are boxes no label may overlap (texts, marks); `soft` boxes a label
    avoids when it can (arrows). `gap` (pixels) keeps placed boxes apart."""

    ax: plt.Axes
    taken: list = field(default_factory=list)
    soft: list = field(default_factory=list)
    gap: float = 0.0

    def box_of(self, artist, pad_pixels: float = 0.0) -> Box:
        """The data box of a drawn artist (a text with its bbox patch, a marker, an arrow)."""
        renderer = self.ax.figure.canvas.get_renderer()
        patch = getattr(artist, "get_bbox_patch", lambda: None)()
        extent = (patch or artist).get_window_extent(renderer).expanded(1.0, 1.0)
        (x0, y0), (x1, y1) = self.ax.transData.inverted().transform(
            [[extent.x0 - pad_pixels, extent.y0 - pad_pixels],
             [extent.x1 + pad_pixels, extent.y1 + pad_pixels]])
        return (min(x0, x1), min(y0, y1), max(x0, x1), max(y0, y1))

    def size(self, text, pad: float) -> tuple[float, float]:
        """The data size of `text` with a box padded by `pad` times its font size."""
        renderer = self.ax.figure.canvas.get_renderer()
        extent = text.get_window_extent(renderer)
        inverse = self.ax.transData.inverted()
        (x0, y0), (x1, y1) = inverse.transform([[0, 0], [extent.width, extent.height]])
        pad_pixels = pad * text.get_fontsize() * self.ax.figure.dpi / 72
        (px0, _), (px1, _) = inverse.transform([[0, 0], [pad_pixels, 0]])
        return (x1 - x0) + 2 * (px1 - px0), (y1 - y0) + 2 * (px1 - px0)

    def _gap(self) -> float:
        inverse = self.ax.transData.inverted()
        (x0, _), (x1, _) = inverse.transform([[0, 0], [self.gap, 0]])
        return abs(x1 - x0)

    def place(self, candidates: Sequence | Callable, label: str, pad: float = 0.15,
              strict: bool = False, **style) -> Box | None:
        """Draw `label` at the first candidate centre where it is free and inside the axes
        (with `soft` boxes: the free one overlapping them least). `candidates` is a list of
        centres or a function of the label's data size (w, h) giving one. When no spot is
        free: `strict` removes the label and returns None, else it goes where it overlaps
        least. Returns its box."""
        text = self.ax.text(0, 0, label, ha="center", va="center", zorder=6,
                            bbox=dict(boxstyle=f"round,pad={pad}", fc="white", ec="none",
                                      alpha=0.85), **style)
        w, h = self.size(text, pad)
        if callable(candidates):
            candidates = candidates(w, h)
        (x0, x1), (y0, y1) = self.ax.get_xlim(), self.ax.get_ylim()
        taken = np.array(self.taken, dtype=float).reshape(-1, 4)
        soft = np.array(self.soft, dtype=float).reshape(-1, 4)
        g = self._gap()
        best, best_cost, free, free_soft = None, np.inf, None, np.inf
        for x, y in candidates:
            box = (x - w / 2 - g, y - h / 2 - g, x + w / 2 + g, y + h / 2 + g)
            cost = _overlap(box, taken)
            if box[0] < x0 or box[2] > x1 or box[1] < y0 or box[3] > y1:
                cost += w * h
            if cost < best_cost:
                best, best_cost = box, cost
            if cost == 0:
                crossing = _overlap(box, soft) if len(soft) else 0.0
                if crossing < free_soft:
                    free, free_soft = box, crossing
                if crossing == 0:
                    break
        if free is not None:
            best = free
        elif strict:
            text.remove()
            return None
        text.set_position(((best[0] + best[2]) / 2, (best[1] + best[3]) / 2))
        self.taken.append(best)
        return best
