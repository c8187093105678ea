"""Reading world files: `load_world(path)`, `world_from_toml(text)` and `world_from_data(tables)`
(worldfile/loader.py)."""

from hg2prism.model.validation import LIMIT_REASON, MAX_EPISODES, MAX_HORIZON, MAX_SEED
from hg2prism.worldfile.loader import load_world, world_from_data, world_from_toml

__all__ = ["load_world", "world_from_toml", "world_from_data", "MAX_EPISODES", "MAX_HORIZON", "MAX_SEED", "LIMIT_REASON"]
