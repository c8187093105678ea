"""The model of the world: the World value, the transition system TS, the automata, the product
TS x DFA and the size guard (the world file is read by hg2prism/worldfile/)."""
