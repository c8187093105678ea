"""A DFA drawn as SVG text, with no Graphviz (issue 25 item 4): `check` writes task.svg and
hypothesis_<i>.svg beside the .hoa and .dot files, readable in any browser.

The layout is deliberately simple and deterministic: the states in columns by their
breadth-first distance from the initial state (the DFA's numbering is breadth-first already),
top to bottom by number within a column; one edge per (state, successor) labelled, as in the
.dot file, with the label classes leading there ("{}" = no proposition); an edge and its reverse
bend to opposite sides; a self-loop is a loop above its state. Final states are double-circled,
sinks grey, the initial state is pointed at from the left.
"""

from __future__ import annotations

from collections import deque
from xml.sax.saxutils import escape

COLUMN, ROW, RADIUS, MARGIN, TOP = 190, 110, 20, 70, 70
BEND = 28     # an edge that is not a straight step to the next column bends by this + 0.3 x its length


def _columns(delta, initial: int, n_states: int) -> list[int]:
    """Each state's column: its breadth-first distance from the initial state (unreachable
    states after the last column)."""
    depth = [-1] * n_states
    depth[initial] = 0
    queue = deque([initial])
    while queue:
        q = queue.popleft()
        for target in map(int, delta[q]):
            if depth[target] < 0:
                depth[target] = depth[q] + 1
                queue.append(target)
    last = max(depth) + 1
    return [d if d >= 0 else last for d in depth]


def _edges(dfa, label_names) -> dict[tuple[int, int], str]:
    """(state, successor) -> the label classes leading there, joined as in to_dot."""
    edges: dict[tuple[int, int], list[str]] = {}
    for q in range(dfa.n_states):
        for k, name in enumerate(label_names):
            edges.setdefault((q, int(dfa.delta[q, k])), []).append(name or "{}")
    return {edge: ", ".join(names) for edge, names in edges.items()}


def _text(x: float, y: float, text: str, size: int = 11, anchor: str = "middle") -> str:
    return (f'<text x="{x:.1f}" y="{y:.1f}" font-size="{size}" text-anchor="{anchor}" '
            f'font-family="sans-serif" stroke="white" stroke-width="3" paint-order="stroke">'
            f"{escape(text)}</text>")


def _edge(start: tuple[float, float], end: tuple[float, float], label: str, bend: float) -> list[str]:
    """A quadratic curve from circle to circle, bent by `bend` to its left, with its label."""
    (x0, y0), (x1, y1) = start, end
    dx, dy = x1 - x0, y1 - y0
    length = max((dx * dx + dy * dy) ** 0.5, 1e-9)
    ux, uy = dx / length, dy / length
    cx, cy = (x0 + x1) / 2 - uy * bend, (y0 + y1) / 2 + ux * bend     # control point
    def towards(x, y, tx, ty):
        vx, vy = tx - x, ty - y
        n = max((vx * vx + vy * vy) ** 0.5, 1e-9)
        return x + vx / n * RADIUS, y + vy / n * RADIUS
    sx, sy = towards(x0, y0, cx, cy)
    ex, ey = towards(x1, y1, cx, cy)
    mx, my = 0.25 * sx + 0.5 * cx + 0.25 * ex, 0.25 * sy + 0.5 * cy + 0.25 * ey
    return [f'<path d="M {sx:.1f} {sy:.1f} Q {cx:.1f} {cy:.1f} {ex:.1f} {ey:.1f}" fill="none" '
            'stroke="black" marker-end="url(#arrow)"/>', _text(mx, my - 4, label, 10)]


def _loop(x: float, y: float, label: str) -> list[str]:
    top = y - RADIUS - 34
    return [f'<path d="M {x - 9:.1f} {y - RADIUS + 2:.1f} C {x - 34:.1f} {top:.1f} '
            f'{x + 34:.1f} {top:.1f} {x + 9:.1f} {y - RADIUS + 2:.1f}" fill="none" '
            'stroke="black" marker-end="url(#arrow)"/>', _text(x, top + 4, label, 10)]


def to_svg(dfa, label_names: tuple[str, ...]) -> str:
    """The DFA as a standalone SVG document (the module docstring says how it is laid out)."""
    column = _columns(dfa.delta, dfa.initial, dfa.n_states)
    rows: dict[int, int] = {}
    place = {}
    for q in range(dfa.n_states):
        place[q] = (MARGIN + 40 + column[q] * COLUMN, TOP + 40 + rows.get(column[q], 0) * ROW)
        rows[column[q]] = rows.get(column[q], 0) + 1
    width = MARGIN * 2 + 40 + max(column) * COLUMN + 120
    height = TOP + 40 + (max(rows.values()) - 1) * ROW + RADIUS + 50
    title = f"DFA of {dfa.formula} (states = q of strategy.json)"
    width = max(width, 7 * len(title) + 2 * MARGIN)
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
           f'viewBox="0 0 {width} {height}">',
           '<defs><marker id="arrow" viewBox="0 0 10 10" refX="10" refY="5" markerWidth="7" '
           'markerHeight="7" orient="auto-start-reverse"><path d="M 0 0 L 10 5 L 0 10 z"/>'
           '</marker></defs>',
           f'<rect width="{width}" height="{height}" fill="white"/>',
           _text(MARGIN, 30, title, 13, "start")]
    x0, y0 = place[dfa.initial]
    out.append(f'<path d="M {x0 - RADIUS - 40} {y0} L {x0 - RADIUS} {y0}" stroke="black" '
               'marker-end="url(#arrow)"/>')
    edges = _edges(dfa, label_names)
    for (q, target), label in edges.items():
        if q == target:
            out += _loop(*place[q], label)
        else:
            (x0, y0), (x1, y1) = place[q], place[target]
            straight = abs(column[target] - column[q]) == 1 and (target, q) not in edges
            length = ((x1 - x0) ** 2 + (y1 - y0) ** 2) ** 0.5
            out += _edge(place[q], place[target], label, 0 if straight else BEND + 0.3 * length)
    for q in range(dfa.n_states):
        x, y = place[q]
        fill = "lightgrey" if q in dfa.sink else "white"
        out.append(f'<circle cx="{x}" cy="{y}" r="{RADIUS}" fill="{fill}" stroke="black"/>')
        if q in dfa.accepting:
            out.append(f'<circle cx="{x}" cy="{y}" r="{RADIUS - 4}" fill="none" stroke="black"/>')
        out.append(_text(x, y + 4, str(q), 12))
        kind = "final" if q in dfa.accepting else "sink" if q in dfa.sink else ""
        if kind:
            out.append(_text(x, y + RADIUS + 14, kind, 10))
    out.append("</svg>")
    return "\n".join(out) + "\n"
