"""A sweep in a few lines: how the deceptive value of world3 depends on how rational P2
believes P1 to be, beside the symmetric baselines (which do not depend on it). world3's feint
needs a P2 who reads P1's moves: 0.75 (V_lead) for beta 0.5 and 2, 1.0 for beta 10. (On world1
the value does not move: P1 never gives P2 evidence against her first guess, whatever weight
she gives it; examples/tour.ipynb sweeps both.)

    python examples/sweep_rationality.py
"""

import dataclasses
from pathlib import Path

import hg2prism

world = hg2prism.load_world(Path(__file__).resolve().parent.parent / "models" / "world3.toml")
reference = hg2prism.baselines(world)
low, high = reference.v_ne_bounds
print(f"V_lead {reference.v_lead:.4f}, V_NE in [{low:.6f}, {high:.6f}]")
for rationality in (0.5, 2.0, 10.0):
    variant = dataclasses.replace(world, rationality=rationality)
    print(f"rationality {rationality:5.1f}: deceptive value "
          f"{hg2prism.solve(variant).deceptive_value:.4f}")
