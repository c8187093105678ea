"""What is computed beside the deceptive value: the symmetric baselines, simulation, detection."""
