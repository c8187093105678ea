"""P1's deceptive strategy: chosen from Storm's values (deceptive.py), written to and read from
strategy.json (records.py)."""
