"""The constants of the fastest-first rule (docs/semantics.md §6): among the moves optimal for
the value, P1 plays the one with the largest discounted probability of reaching the goal,
W = max over optimal moves of E[DISCOUNT^steps; goal], so that it never stalls. Every
strategy read this way takes them from here:

- the deceptive strategy on Storm's values (strategy/deceptive.py) and the robust one on its
  certified worst-case values (strategy/robust.py), optimal within STORM_SLACK, their scores
  iterated until they change by less than SCORE_STOP;
- P1's answers in P2's games and the naive strategy (opponent/perceptual_games.py
  `fastest_moves`, analyses/deception_value.py `naive_answers`), on values solved exactly,
  optimal within EXACT_SLACK, scores iterated to EXACT_SCORE_STOP.

Scores within a relative RELATIVE_TIE of the best are tied where a rule says so, and ties go
to the first action slot. The slacks differ with where the values come from, and the
strategies and documents were computed with them as they are: changing one changes
strategies.
"""

DISCOUNT = 0.9              # how strongly P1 prefers finishing soon among optimal moves
STORM_SLACK = 1e-8          # Storm's values are sound to 1e-10: choices this close are optimal
EXACT_SLACK = 1e-9          # values solved exactly (numpy): moves this close are optimal
SCORE_STOP = 1e-9           # the scores' iteration stops below this change (enough to rank)
EXACT_SCORE_STOP = 1e-12    # ... on the small exact games
RELATIVE_TIE = 1e-12        # scores this close (relative) are tied: the first move wins
MAX_SCORE_SWEEPS = 1000
