"""Reading world files: `load_world(path)` and `world_from_toml(text)` (worldfile/loader.py)."""

from hg2prism.worldfile.loader import MAX_EPISODES, MAX_HORIZON, LIMIT_REASON, load_world, world_from_toml

__all__ = ["load_world", "world_from_toml", "MAX_EPISODES", "MAX_HORIZON", "LIMIT_REASON"]
