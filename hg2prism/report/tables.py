"""What a researcher reads: the summary printed after a run."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from hg2prism.results import CheckResults, RunResults


@dataclass(frozen=True)
class CompletionRow:
    """A row of the completion table (and a curve of the completion figure): the strategy
    pair's key in `results.simulation`, its information setting and policies, and the result
    holding its exact value."""

    key: str
    information: str
    p1: str
    p2: str
    exact: str


COMPLETION_ROWS = (
    CompletionRow("deceptive", "Asymmetric", "deceptive π1*", "inference-driven π2",
                  "deceptive_value"),
    CompletionRow("static", "Asymmetric, P2 never revises", "best response",
                  "π2 of her first guess", "v_static"),
    CompletionRow("naive", "Asymmetric, P1 ignores P2's misperception", "leader-game answer",
                  "inference-driven π2", "v_naive"),
    CompletionRow("nash", "Symmetric, Nash", "π1^NE", "π2^NE", "v_ne"),
    CompletionRow("leader", "Symmetric, leader", "best response", "leader π2", "v_lead"),
)


def completion_table(results: RunResults) -> str:
    """The paper's Table I, with the leader row and the two rows of docs/semantics.md §11 added
    (docs/semantics.md §8, table.md): a row per COMPLETION_ROWS."""
    sim = results.simulation
    rows = [(row.information, row.p1, row.p2, getattr(results, row.exact), getattr(sim, row.key))
            for row in COMPLETION_ROWS]
    lines = [
        f"Completion of the task `{results.parameters.formula}` in {results.world} "
        f"(simulation: horizon {sim.horizon}, seed {sim.seed})",
        "",
        "| information | P1 policy | P2 policy | exact value | exact within horizon | simulated completion (95% CI) | episodes | cut by horizon |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for info, p1, p2, exact, s in rows:
        low, high = s.ci95
        lines.append(f"| {info} | {p1} | {p2} | {exact:.4f} | {s.exact_within_horizon:.4f} "
                     f"| {s.rate:.4f} [{low:.4f}, {high:.4f}] | {s.episodes} | {s.truncated} |")
    lines.append("")
    lines.append(f"Exact value: the probability of ever completing the task (Pmax for the asymmetric "
                 f"row, V_static and V_naive for the two below it, V_NE and V_lead for the "
                 f"symmetric ones; P1's extracted Nash strategy "
                 f"guarantees {results.v_ne_p1_guaranteed:.4f}). Exact within horizon: the "
                 f"probability of completing it within {sim.horizon} steps when both play the "
                 f"strategies simulated, which the simulated rate estimates.")
    lines.append("")
    lines.append(f"Value of deception (deceptive value - V_naive): {results.value_of_deception:.4f}. "
                 f"P2 changed her hypothesis in {sim.deceptive.p2_switched:.1%} of the deceptive "
                 f"episodes ({sim.deceptive.p2_switches_mean:.2f} changes per episode on average) "
                 f"and in {sim.naive.p2_switched:.1%} of the naive ones; at a step after which the "
                 f"episode went on (a change she could act on) in "
                 f"{sim.deceptive.p2_switched_in_play:.1%} and "
                 f"{sim.naive.p2_switched_in_play:.1%}.")
    return "\n".join(lines) + "\n"


def written(out: Path, files: list[str]) -> str:
    return f"wrote {out}/{{{', '.join(files)}}}"


def _steps(value: float | None, infinite: str) -> str:
    return infinite if value is None else f"{value:.2f}"


def _objective_line(results: CheckResults) -> str:
    """The exported strategy's objective and its expected numbers of steps."""
    o = results.objective
    what = {"pmax": "Pmax", "lexicographic": "Pmax, then fewest expected steps",
            "bounded": f"Pmax=? [F<={o.bound} \"goal\"] = {o.value:.6f}"}[o.name]
    to_goal = (f"{o.expected_steps_to_goal:.2f} to the goal when reached"
               if o.expected_steps_to_goal is not None else "the goal is never reached")
    return (f"  strategy         {what}; expected steps {_steps(o.expected_steps, 'infinite')} "
            f"to the end, {to_goal}")


def summary(results: CheckResults, out: Path, files: list[str]) -> str:
    """What `check` and `run` print: the values, the hypergame's size and the files written
    (with `run`, `results` is a RunResults and V_NE is shown too)."""
    typed = f" (P2 of type {results.p2_type})" if results.p2_type else ""
    return "\n".join([
        f"{results.world}{typed}:",
        f"  deceptive value  {results.deceptive_value:.6f}   P1 against P2's inference (Pmax, Storm)",
        f"  v_lead           {results.v_lead:.6f}   P2 knows the task and commits first each step",
    ] + ([f"  v_ne             {results.v_ne:.6f}   in [{results.v_ne_bounds[0]:.10f}, "
          f"{results.v_ne_bounds[1]:.10f}], both players mixing, P2 knowing the task",
          f"  v_static         {results.v_static:.6f}   P2 never revises her first guess",
          f"  v_naive          {results.v_naive:.6f}   P1 plays as if P2 knew the task, against her inference",
          f"  deception worth  {results.value_of_deception:.6f}   deceptive value - v_naive"]
         if isinstance(results, RunResults) else []) + [
        _objective_line(results),
        f"  hypergame        {results.states} states, {results.transitions} transitions (canonical); "
        f"Storm: {results.storm_states} states, {results.storm_transitions} transitions, "
        f"{results.storm_choices} choices",
        f"  wrote            {out}/{{{', '.join(files)}}}",
    ] + ([f"  warning          Storm method {results.storm_method!r} is not sound: the values "
          f"above are not certified to 1e-10"] if not results.sound else []))
