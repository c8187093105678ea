"""A world written inline, solved and simulated: the deceptive value against simulation.

    python examples/inline_world.py
"""

import hg2prism

WORLD = '''
name = "corridor"

[grid]
map = """
#######
#@..tA#
#.t...#
#....B#
#######
"""

[robot]
slip = 0.1

[task]
formula = "!obs U A"

[adversary]
traps = 1
hypotheses = ["!obs U A", "!obs U B"]
initial_hypothesis = 1

[inference]
window = 2
threshold = 1.5
rationality = 5.0
'''

world = hg2prism.world_from_toml(WORLD, name="corridor")
solution = hg2prism.solve(world)
played = hg2prism.simulate(solution, episodes=2000, horizon=200, seed=1)
low, high = played.ci95
print(f"{world.name}: deceptive value {solution.deceptive_value:.4f}; simulated "
      f"{played.rate:.4f} [{low:.4f}, {high:.4f}] over {played.episodes} episodes")
