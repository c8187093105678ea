"""What a researcher reads: the summary printed after a run."""

from __future__ import annotations

from pathlib import Path


def summary(results: dict, out: Path) -> str:
    files = sorted(p.name for p in out.iterdir() if p.is_file() and not p.name.startswith("."))
    return "\n".join([
        f"{results['world']}:",
        f"  deceptive value  {results['deceptive_value']:.6f}   P1 against P2's inference (Pmax, Storm)",
        f"  v_lead           {results['v_lead']:.6f}   P2 knows the task and commits first each step",
        f"  hypergame        {results['states']} states, {results['transitions']} transitions (canonical); "
        f"Storm: {results['storm_states']} states, {results['storm_transitions']} transitions, "
        f"{results['storm_choices']} choices",
        f"  wrote            {out}/{{{', '.join(files)}}}",
    ])
