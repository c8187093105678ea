"""Studies over many runs: parameter sweeps, the detection experiment, the benchmark."""
