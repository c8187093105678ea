"""The model of the world: the world file, the transition system TS, the automata, the size guard."""
