"""P2, the opponent: her perceptual games G(x) and her inference of P1's task."""
