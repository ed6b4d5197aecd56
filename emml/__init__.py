"""EMML: a reproduction harness for "Embodied Multimodal Multitask Learning" (Chaplot et al., 2019,
arXiv:1902.01385). Importing the package registers the Gymnasium environments `emml/Doom-v0` and `emml/House-v0`."""

import gymnasium as gym

__version__ = "0.1.0"

if "emml/Doom-v0" not in gym.registry:
    gym.register(id="emml/Doom-v0", entry_point="emml.envs.doom:DoomEnv", disable_env_checker=True)
if "emml/House-v0" not in gym.registry:
    gym.register(id="emml/House-v0", entry_point="emml.envs.house:HouseEnv", disable_env_checker=True)
