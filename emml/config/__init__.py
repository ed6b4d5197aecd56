"""The configs and where things are: the config schema (schema.py), the cost profiles of reproduce/profiles.toml
(profiles.py), the environment kinds (env_kinds.py), the conv geometry (geometry.py) and the project's folders
(paths.py). The lowest wing: it imports no other part of emml."""
