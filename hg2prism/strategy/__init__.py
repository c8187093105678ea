"""P1's strategies: the Policy protocol they all implement (policy.py); the deceptive strategy
chosen from Storm's values (deceptive.py), written to and read from strategy.json (records.py)."""
