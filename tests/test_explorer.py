"""explorer.html (issue #26 items 4 and 5): the page `run` writes beside the figures.

Without a browser: the page is self-contained (no external resource) and its data agrees with
itself (what P2 would believe after the move P1 plays is what she believes at the next step).
In headless Chromium (Debian's `chromium`, driven by Playwright; skipped, saying why, when
either is missing): world1's and world3's pages are stepped through the whole drawn episode
with the keyboard, and at every state the values, the traps and the belief the page shows
are compared with strategy.json, results.json and tests/reference.py (the reference's P2
strategy, its inference and CUSUM scores computed from its softmax model of P1); the page
logs no error, and a screenshot at 1280x800 is not blank.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

import reference
from conftest import MODELS
from hg2prism import cli

WORLDS = ("world1", "world3")
VIEWPORT = {"width": 1280, "height": 800}
TOLERANCE = 1e-6        # the reference's and the package's scores: separate solvers


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    outs = {}
    for name in WORLDS:
        out = tmp_path_factory.mktemp("explorer") / name
        assert cli.main(["run", str(MODELS / f"{name}.toml"), "--out", str(out),
                         "--episodes", "200"]) == 0
        outs[name] = out
    return outs


def page_data(path: Path) -> dict:
    text = path.read_text(encoding="utf-8")
    match = re.search(r'<script type="application/json" id="data">(.*?)</script>', text, re.S)
    assert match, "the page holds its data inline"
    return json.loads(match.group(1))


def test_explorer_is_self_contained(runs: dict[str, Path]) -> None:
    for name, out in runs.items():
        text = (out / "explorer.html").read_text(encoding="utf-8")
        assert text.startswith("<!DOCTYPE html>")
        # no file or address is loaded: scripts and styles are inline, the only URL is SVG's
        # namespace name
        assert not re.search(r"<(script|img|link|iframe)[^>]*\b(src|href)=", text)
        assert set(re.findall(r"https?://[^\s\"')]+", text)) <= {"http://www.w3.org/2000/svg"}
        assert "@import" not in text and "url(http" not in text


def test_explorer_data_agrees_with_the_run(runs: dict[str, Path]) -> None:
    """The drawn episode is results.json's, every candidate of the seed set is there, and
    P2's answer to the move P1 played is the belief shown at the next step."""
    for name, out in runs.items():
        data = page_data(out / "explorer.html")
        drawn = json.loads((out / "results.json").read_text())["episode"]
        first, last = drawn["seed_set"]
        assert [e["seed"] for e in data["episodes"]] == list(range(first, last + 1))
        (episode,) = [e for e in data["episodes"] if e["drawn"]]
        assert (episode["seed"], len(episode["steps"]), episode["outcome"]) == (
            drawn["seed"], drawn["steps"], drawn["outcome"])
        for e in data["episodes"]:
            states, steps = e["states"], e["steps"]
            assert len(states) == len(steps) + 1
            assert [s["n"] for s in steps] == list(range(1, len(steps) + 1))
            for n, step in enumerate(steps, start=1):
                before, after = states[n - 1], states[n]
                assert step["start"] == before["place"]
                record = data["records"][before["record"]]
                assert record["state"] == data["states"][before["place"]]
                assert set(record["values"]) == {a["move"] for a in
                                                 data["answers"][before["answers"]]}
                assert step["landing"] == after["place"]
                (played,) = [a for a in data["answers"][before["answers"]]
                             if a["move"] == step["action"]]
                assert played["hypothesis"] == after["belief"]["hypothesis"]
                assert played["belief"] == after["belief"]["belief"]
                assert after["belief"]["acted"] == step["hypothesis"]
                assert after["belief"]["changed"] == (after["belief"]["hypothesis"]
                                                      != step["hypothesis"])


# ---- in a browser ----

def _browser():
    """Playwright's Chromium on the system's chromium, or pytest.skip saying why not."""
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.skip("Playwright for Python is not installed (pip install playwright)")
    executable = shutil.which("chromium") or shutil.which("chromium-browser")
    if executable is None:
        pytest.skip("no chromium on PATH (Debian: apt-get install chromium; .ci/run does)")
    return sync_playwright, executable


@pytest.fixture(scope="module")
def browser():
    sync_playwright, executable = _browser()
    manager = sync_playwright().start()
    try:
        try:
            chromium = manager.chromium.launch(executable_path=executable,
                                               args=["--no-sandbox"])
        except Exception as err:    # noqa: BLE001: the browser cannot run here
            pytest.skip(f"chromium at {executable} does not start under Playwright: "
                        f"{str(err).splitlines()[0]}")
        yield chromium
        chromium.close()
    finally:
        manager.stop()


READ_STATE = """() => {
  const q = (s) => document.querySelector(s);
  const data = (e) => e ? Object.assign({}, e.dataset) : null;
  return {
    step: Number(q('#step').dataset.step),
    episode: data(q('#episode')),
    robot: q('#robot').dataset.state,
    belief: data(q('#belief')),
    scores: [...document.querySelectorAll('#beliefbox tr.score')].map((r) => [Number(r.dataset.x), r.dataset.value]),
    record: data(q('#record')),
    traps: data(q('#traps')),
    trapMarks: [...document.querySelectorAll('#dynamic g.trap')].map((g) => g.dataset.state),
    moves: [...document.querySelectorAll('#moves tr.move')].map((r) => Object.assign({}, r.dataset)),
  };
}"""


def _cell(name: str) -> tuple[int, int]:
    x, y = reference._cell_of(name)
    return x, y


def _z_scores(ref: reference.World, hypothesis: int, window: list, observation) -> list[float]:
    """CUSUM scores Z_x (docs/semantics.md §5) from the reference's log-likelihood ratios:
    Z_x = max(0, Z_x + r) over the window with the new observation, 0 for the current x."""
    recent = (list(window) + [observation])[-ref.window:]
    scores = []
    for x in range(len(ref.hyps)):
        z = 0.0
        if x != hypothesis:
            for v, a in recent:
                z = max(0.0, z + ref.r(x, hypothesis, v, a))
        scores.append(z)
    return scores


def _check_state(shown: dict, records: dict, ref: reference.Reference, previous: dict | None
                 ) -> dict:
    """One state of the page against strategy.json and the reference; returns what the next
    state's belief must be (P2's answer to the move played)."""
    key = json.loads(shown["record"]["key"])
    record = records[json.dumps(key, sort_keys=True)]
    assert shown["robot"] == record["state"]
    values = {m["move"]: float(m["value"]) if m["value"] else None for m in shown["moves"]}
    assert values == record["values"]
    (chosen,) = [m["move"] for m in shown["moves"] if m["chosen"] == "true"]
    assert chosen == record["action"]
    cell = _cell(record["state"])
    hypothesis = record["hypothesis"]
    window = [(_cell(w["state"]), w["action"]) for w in record["window"]]
    # the traps P2 sets for the next step: her strategy for the hypothesis she acts on
    assert int(shown["traps"]["hypothesis"]) == hypothesis
    traps = sorted(_cell(t) for t in json.loads(shown["traps"]["traps"]))
    assert traps == sorted(ref.trap_strategy(hypothesis, cell))
    assert sorted(_cell(t) for t in shown["trapMarks"]) == traps
    # what she would believe after each move
    answers = {}
    for move in shown["moves"]:
        after, _ = ref.infer(hypothesis, window, (cell, move["move"]))
        scores = _z_scores(ref.world, hypothesis, window, (cell, move["move"]))
        assert int(move["after"]) == after
        assert json.loads(move["belief"]) == pytest.approx(scores, abs=TOLERANCE)
        answers[move["move"]] = (after, scores, after != hypothesis)
    if previous is not None:        # this state's belief is P2's answer to the last move
        after, scores, changed = previous
        assert int(shown["belief"]["hypothesis"]) == after
        assert shown["belief"]["changed"] == str(changed).lower()
        assert [float(v) for _, v in sorted(shown["scores"])] == pytest.approx(scores,
                                                                                 abs=TOLERANCE)
    return answers[chosen]


@pytest.mark.parametrize("name", WORLDS)
def test_explorer_in_chromium(name: str, runs: dict[str, Path], browser, tmp_path: Path
                              ) -> None:
    out = runs[name]
    results = json.loads((out / "results.json").read_text())
    drawn = results["episode"]
    records = {}
    for record in json.loads((out / "strategy.json").read_text()):
        key = {k: record[k] for k in ("state", "standing", "countdown", "q", "hypothesis",
                                      "window")}
        records.setdefault(json.dumps(key, sort_keys=True), record)
    ref = reference.solve(MODELS / f"{name}.toml")
    threshold = results["parameters"]["threshold"]

    page = browser.new_page(viewport=VIEWPORT)
    errors: list[str] = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda err: errors.append(str(err)))
    page.goto((out / "explorer.html").as_uri())

    shown = page.evaluate(READ_STATE)
    assert shown["episode"] == {"seed": str(drawn["seed"]), "steps": str(drawn["steps"]),
                                "outcome": drawn["outcome"]}
    assert shown["step"] == 0 and shown["belief"]["threshold"] == str(threshold)
    assert int(shown["belief"]["hypothesis"]) == ref.world.h0
    previous = None
    changes = []
    for n in range(drawn["steps"] + 1):
        shown = page.evaluate(READ_STATE) if n else shown
        assert shown["step"] == n
        if n and shown["belief"]["changed"] == "true":
            changes.append(n)
        if n < drawn["steps"]:
            previous = _check_state(shown, records, ref, previous)
            page.keyboard.press("ArrowRight")
        else:       # the end: P2's answer to the last move, no further move
            after, scores, _ = previous
            assert int(shown["belief"]["hypothesis"]) == after
            assert shown["moves"] == [] and shown["record"] is None
    page.keyboard.press("ArrowRight")           # nothing beyond the end
    assert page.evaluate(READ_STATE)["step"] == drawn["steps"]
    page.keyboard.press("ArrowLeft")
    assert page.evaluate(READ_STATE)["step"] == drawn["steps"] - 1
    page.keyboard.press("Home")
    page.click("#next")                          # the mouse
    assert page.evaluate(READ_STATE)["step"] == 1
    page.keyboard.press("ArrowDown")             # the next candidate episode, from its start
    other = page.evaluate(READ_STATE)
    assert other["step"] == 0 and other["episode"]["seed"] == str(
        drawn["seed"] + 1 if drawn["seed"] < drawn["seed_set"][1] else drawn["seed_set"][0])
    # with the focus on the episode list (after choosing from it), the arrows still step
    page.select_option("#seed", index=0)
    page.focus("#seed")
    chosen = page.evaluate(READ_STATE)
    page.keyboard.press("ArrowRight")
    stepped = page.evaluate(READ_STATE)
    assert stepped["step"] == chosen["step"] + 1 and stepped["episode"] == chosen["episode"]
    page.keyboard.press("ArrowDown")             # the list's own key: the next episode
    assert page.evaluate(READ_STATE)["episode"] != chosen["episode"]
    if name == "world3":       # the feint: she changes her mind during the drawn episode
        assert changes
    shot = tmp_path / f"{name}.png"
    page.keyboard.press("End")
    page.screenshot(path=str(shot))
    repeated = 0
    for _ in range(12):                 # a dozen candidates, each to its end
        repeated += _assert_steps_side_by_side(page.evaluate(READ_STEPS))
        page.keyboard.press("ArrowDown")
        page.keyboard.press("End")
    assert repeated, "some episode crosses a segment twice (else the check above tests nothing)"
    page.close()
    assert errors == []
    _assert_not_blank(shot)


READ_STEPS = """() => [...document.querySelectorAll('#dynamic .step')].map((e) => ({
  step: Number(e.dataset.step), segment: e.dataset.segment, tag: e.tagName,
  at: e.tagName === 'line' ? [e.x1, e.y1, e.x2, e.y2].map((a) => a.baseVal.value)
                           : [e.cx.baseVal.value, e.cy.baseVal.value]}))"""


def _assert_steps_side_by_side(steps: list[dict]) -> int:
    """Every step up to the last is drawn, and steps over the same segment (or staying at the
    same state) are not drawn over each other; returns how many steps repeat a segment."""
    assert [s["step"] for s in steps] == list(range(1, len(steps) + 1))
    drawn = [tuple(round(a, 1) for a in s["at"]) for s in steps]
    assert len(set(drawn)) == len(drawn), "two steps drawn on top of each other"
    return len(steps) - len({s["segment"] for s in steps})


def _assert_not_blank(path: Path) -> None:
    from PIL import Image

    with Image.open(path) as image:
        assert image.size == (VIEWPORT["width"], VIEWPORT["height"])
        rgb = image.convert("RGB")
        colours = rgb.getcolors(maxcolors=1 << 20)
        assert colours is not None and len(colours) > 50
        # no single colour covers nearly everything (a blank or error page)
        assert max(count for count, _ in colours) < 0.9 * rgb.size[0] * rgb.size[1]
        # the map is drawn: its left half holds dark cells or text
        left = rgb.crop((0, 60, rgb.size[0] // 2, rgb.size[1] - 100)).convert("L")
        assert left.getextrema()[0] < 80


def test_explorer_shows_a_change_of_mind_at_the_step_of_the_belief_trace(runs: dict[str, Path]
                                                                         ) -> None:
    """Step numbering (issue #26 item 2): the explorer marks a change of mind at step n exactly
    when belief.png's trace does (analyses/episodes.belief_trace: after[n-1] != before[n-1]);
    world3's drawn episode has one."""
    from hg2prism import pipeline
    from hg2prism.analyses import episodes, simulation
    from hg2prism.strategy.records import Strategy
    from hg2prism.worldfile import load_world

    world = load_world(MODELS / "world3.toml")
    out = runs["world3"]
    analysis = pipeline.analyse(world)
    strategy = Strategy.load(out / "strategy.json", analysis.ts)
    seed = json.loads((out / "results.json").read_text())["episode"]["seed"]
    steps: list = []
    simulation.simulate_deceptive(analysis, strategy, 1, world.simulation.horizon, seed,
                                  observer=steps.append, progress=False)
    trace = episodes.belief_trace(analysis.inference, steps)
    changes = [n for n in range(1, len(steps) + 1) if trace.after[n - 1] != trace.before[n - 1]]
    (episode,) = [e for e in page_data(out / "explorer.html")["episodes"] if e["drawn"]]
    shown = [n for n, state in enumerate(episode["states"]) if state["belief"]["changed"]]
    assert changes and shown == changes
    assert [s["belief"]["hypothesis"] for s in episode["states"][1:]] == list(trace.after)
    assert [s["belief"]["belief"] for s in episode["states"][1:]] == [list(v) for v in trace.values]


READ_EDGES = """() => {
  const boxes = [...document.querySelectorAll('#base > rect')].map((r) =>
    [r.x.baseVal.value, r.y.baseVal.value, r.width.baseVal.value, r.height.baseVal.value]);
  const edges = [...document.querySelectorAll('#base > line.edge')].map((e) => ({
    edge: e.dataset.edge, at: [e.x1, e.y1, e.x2, e.y2].map((a) => a.baseVal.value)}));
  return {boxes: boxes, edges: edges, states: JSON.parse(document.getElementById('data').textContent).states};
}"""


def _explore(world, browser, folder: Path):
    """`hg2prism run` on the world's arena-world file, and its explorer.html opened in Chromium:
    (the page, the list its errors are collected in)."""
    from hg2prism.frontends.arena import to_toml

    path = folder / f"{world.name}.toml"
    path.write_text(to_toml(world))
    out = folder / "out"
    assert cli.main(["run", str(path), "--out", str(out), "--episodes", "20"]) == 0
    page = browser.new_page(viewport=VIEWPORT)
    errors: list[str] = []
    page.on("pageerror", lambda err: errors.append(str(err)))
    page.goto((out / "explorer.html").as_uri())
    return page, errors


def test_arena_edges_show_their_direction(browser, tmp_path: Path) -> None:
    """An arena world's explorer draws each edge from box border to box border, so that its
    arrowhead is not hidden under the target's box (it was: the edges showed no direction),
    and the two edges of a 2-cycle side by side (they were drawn one over the other)."""
    import networkx as nx

    import hg2prism

    graph = nx.DiGraph()
    for u, v, p in ((1, 2, 0.5), (2, 1, 0.5), (2, 3, 0.4), (1, 4, 0.3)):
        graph.add_edge(u, v, p=p)
    world = hg2prism.world_from_graph(graph, entries=[1], task="F asset3", trap_candidates=[2],
                                      name="cycle")
    page, errors = _explore(world, browser, tmp_path)
    shown = page.evaluate(READ_EDGES)
    page.close()
    assert errors == []
    index = {name: i for i, name in enumerate(shown["states"])}
    boxes = shown["boxes"]
    assert len(boxes) == len(index)

    def inside(point: list[float], box: list[float]) -> bool:
        x, y, w, h = box
        return x < point[0] < x + w and y < point[1] < y + h

    drawn = {}
    for edge in shown["edges"]:
        u, v = edge["edge"].split(">")
        x1, y1, x2, y2 = edge["at"]
        assert not inside([x2, y2], boxes[index[v]]), edge      # the arrowhead is visible
        assert not inside([x1, y1], boxes[index[u]]), edge
        drawn[(u, v)] = ((x1 + x2) / 2, (y1 + y2) / 2)
    assert {("n1", "n2"), ("n2", "n1"), ("outside", "n1")} <= set(drawn)
    (ax, ay), (bx, by) = drawn[("n1", "n2")], drawn[("n2", "n1")]
    assert ((ax - bx) ** 2 + (ay - by) ** 2) ** 0.5 >= 6      # side by side


READ_NODES = """() => {
  const rects = [...document.querySelectorAll('#base > rect')].map((r) =>
    [r.x.baseVal.value + r.width.baseVal.value / 2, r.y.baseVal.value + r.height.baseVal.value / 2]);
  const svg = document.getElementById('map'), box = svg.getBoundingClientRect();
  const view = svg.viewBox.baseVal, robot = document.getElementById('robot');
  // the map's own units (its viewBox) are the pixels it was laid out at
  const unit = Math.min(box.width / view.width, box.height / view.height);
  return {centres: rects, width: view.width, height: view.height, unit: unit,
          left: box.left + (box.width - view.width * unit) / 2,
          top: box.top + (box.height - view.height * unit) / 2,
          robot: [robot.cx.baseVal.value, robot.cy.baseVal.value], at: robot.dataset.state,
          states: JSON.parse(document.getElementById('data').textContent).states};
}"""


def test_a_large_graph_is_explored_zoomed_in(browser, tmp_path: Path) -> None:
    """A 122-state attack graph crowds the map fitted whole (its states overlapped): the page
    starts zoomed in, the closest two states NODE_PITCH = 26 px apart and the start state in the
    middle; the wheel zooms about the pointer, dragging moves the map, a double-click shows it
    whole, and the keys still step the episode on the moved map."""
    import random

    import networkx as nx

    import hg2prism

    rng = random.Random(5)
    graph = nx.DiGraph()
    rows = [list(range(i * 20, (i + 1) * 20)) for i in range(6)]
    for here, there in zip(rows, rows[1:]):
        for u in here:
            for v in rng.sample(there, 2):
                graph.add_edge(u, v, p=0.8)
    for u in rows[-1]:
        graph.add_edge(u, 900, p=0.9)
    world = hg2prism.world_from_graph(graph, entries=rows[0], task="F asset900",
                                      trap_candidates=rows[3][:4], name="layers")
    page, errors = _explore(world, browser, tmp_path)

    def closest(centres) -> float:
        return min(((a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2) ** 0.5
                   for i, a in enumerate(centres) for b in centres[i + 1:])

    first = page.evaluate(READ_NODES)
    start = first["centres"][first["states"].index("outside")]
    assert closest(first["centres"]) == pytest.approx(26, abs=0.01)
    assert start == pytest.approx([first["width"] / 2, first["height"] / 2], abs=0.5)
    # the wheel, over the start state: it stays under the pointer, the others move apart
    unit = first["unit"]
    page.mouse.move(first["left"] + start[0] * unit, first["top"] + start[1] * unit)
    page.mouse.wheel(0, -300)
    zoomed = page.evaluate(READ_NODES)
    assert zoomed["centres"][first["states"].index("outside")] == pytest.approx(start, abs=0.5)
    assert closest(zoomed["centres"]) > 26 * 1.2
    # dragging moves every state by the drag
    page.mouse.down()
    page.mouse.move(first["left"] + start[0] * unit + 100 * unit,
                    first["top"] + start[1] * unit + 40 * unit, steps=4)
    page.mouse.up()
    moved = page.evaluate(READ_NODES)
    shifts = {(round(b[0] - a[0], 3), round(b[1] - a[1], 3))
              for a, b in zip(zoomed["centres"], moved["centres"])}
    assert shifts == {(100.0, 40.0)}
    # the keys step on the moved map: the ring is on the state the step reached
    page.keyboard.press("ArrowRight")
    stepped = page.evaluate(READ_NODES)
    assert stepped["robot"] == pytest.approx(
        stepped["centres"][stepped["states"].index(stepped["at"])], abs=0.5)
    assert stepped["at"] != "outside"
    # a double-click shows the whole map: crowded, inside the frame
    page.mouse.dblclick(first["left"] + 20, first["top"] + 20)
    whole = page.evaluate(READ_NODES)
    page.close()
    assert errors == []
    assert closest(whole["centres"]) < 26
    assert all(0 <= x <= whole["width"] and 0 <= y <= whole["height"]
               for x, y in whole["centres"])


MAP_FIT = """() => {
  const svg = document.getElementById('map'), box = svg.getBoundingClientRect();
  const view = svg.viewBox.baseVal;
  return [box.width, box.height, view.width, view.height];
}"""


def test_the_map_is_drawn_at_its_box_size(runs: dict[str, Path], browser) -> None:
    """The map's units are its box's pixels once the page has filled (the panels below the map
    shrink its box after the first draw: world1's map was drawn about 6 % too small), and
    again after the window is resized."""
    page = browser.new_page(viewport=VIEWPORT)
    errors: list[str] = []
    page.on("pageerror", lambda err: errors.append(str(err)))
    page.goto((runs["world1"] / "explorer.html").as_uri())
    page.wait_for_timeout(200)          # ResizeObserver reports after the first layout
    for size in (VIEWPORT, {"width": 1000, "height": 700}):
        page.set_viewport_size(size)
        page.wait_for_timeout(200)
        width, height, view_width, view_height = page.evaluate(MAP_FIT)
        assert (view_width, view_height) == pytest.approx((width, height), abs=0.5), size
    page.close()
    assert errors == []
