"""The PRISM models hg2prism writes: the hypergame MDP and the games for PRISM-games."""
