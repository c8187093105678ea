"""What is computed beside the deceptive value: the symmetric baselines, the value of deception,
simulation, detection; all that plays P1 against P2 in Python steps the hypergame with its one
successor function (successor.py)."""
