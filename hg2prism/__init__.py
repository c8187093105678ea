"""hg2prism: deceptive strategies in dynamic hypergames, checked with Storm.

The pipeline, one module per stage:

    world      -> load and validate a world file (SPEC §1)
    dynamics   -> the transition system TS: cells, labels, trap sets, P(v'|v,a1,a2) (SPEC §2)
    automata   -> Spot: co-safe LTL -> complete DFA (SPEC §3)
    games      -> P2's perceptual games G(x): values, trap strategy, softmax model of P1 (SPEC §4)
    inference  -> P2's sliding-window CUSUM inference (SPEC §5)
    hypergame  -> the hypergame MDP rendered as a structured PRISM model (SPEC §6)
    storm      -> Storm: build, check Pmax, export the deceptive strategy (SPEC §6)
    pipeline   -> runs the stages for one world and writes its outputs
"""

__version__ = "0.1.0"
