"""Quick start: solve world1 and ask the strategy for P1's first move.

    python examples/quick_start.py
"""

from pathlib import Path

import hg2prism

world = hg2prism.load_world(Path(__file__).resolve().parent.parent / "models" / "world1.toml")
solution = hg2prism.solve(world)                  # Storm, sound to 1e-10; writes nothing
print(f"deceptive value {solution.deceptive_value:.6f} over {solution.states} states "
      f"(leader baseline {solution.v_lead:.6f})")

# The initial state's record carries "initial": true (it is written first, but look it up): the
# robot's start (a grid's states are named x{x}_y{y}, so world1's start (2, 4) is x2_y4), the task
# DFA's state after reading its label, P2's first hypothesis and an empty window.
start = next(record for record in solution.strategy.records if record.get("initial"))
print("start state:", start["state"])                              # start state: x2_y4
print("first move:", solution.strategy.move(state=start["state"], q=start["q"],
                                            hypothesis=start["hypothesis"]))   # first move: W
