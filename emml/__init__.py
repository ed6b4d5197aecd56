"""EMML: a reproduction harness for "Embodied Multimodal Multitask Learning" (Chaplot et al., 2019,
arXiv:1902.01385). Importing the package registers the Gymnasium environments `emml/Doom-v0` and `emml/House-v0`."""

import gymnasium as gym

from emml.config.env_kinds import GYM_ENVS

__version__ = "0.1.0"

for _env in GYM_ENVS.values():  # declared with the env kinds (emml/config/env_kinds.py)
    if _env.gym_id not in gym.registry:
        gym.register(
            id=_env.gym_id,
            entry_point=_env.entry_point,
            max_episode_steps=_env.max_episode_steps,
            disable_env_checker=True,
        )
del _env
