"""Stable-Baselines3 training and headless evaluation for the parallel-robot environments.

Training is an extra: ``pip install 'parallel-robot-gym[train]'`` (``[sweep]`` adds Ray Tune). Without it, importing
this package raises ``ModuleNotFoundError`` naming the extra; ``envs`` needs none of it.
"""

from envs._extras import require_all

#: The modules of the ``train`` extra (pyproject.toml), checked without importing them.
TRAIN_MODULES = (
    "torch",
    "stable_baselines3",
    "sb3_contrib",
    "yaml",
    "tqdm",
    "rich",
    "imageio",
    "matplotlib",
    "rliable",
)

require_all(TRAIN_MODULES, "train", "training")
