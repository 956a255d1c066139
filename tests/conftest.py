import os
import sys

# tests import their helpers (scene_builders, stats_util) as top-level modules
sys.path.insert(0, os.path.dirname(__file__))
