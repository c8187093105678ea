"""Quick start: solve world1 and ask the strategy for P1's first move.

    python examples/quick_start.py
"""

from pathlib import Path

import hg2prism

world = hg2prism.load_world(Path(__file__).resolve().parent.parent / "models" / "world1.toml")
solution = hg2prism.solve(world)                  # Storm, sound to 1e-10; writes nothing
print(f"deceptive value {solution.deceptive_value:.6f} over {solution.states} states "
      f"(leader baseline {solution.v_lead:.6f})")

# The robot starts at (2, 3); the task DFA has read that cell's label (state 1 of Spot's
# numbering); P2 starts with hypothesis 0 and an empty window.
print("first move:", solution.strategy.move(cell=(2, 3), q=solution.strategy.records[0]["q"],
                                            hypothesis=0))
