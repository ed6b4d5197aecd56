"""A run's name: the one owner of how a run's identity is spelled as the name of its run dir.

A name is the fields a reader looks for (`spelled_name`: model, difficulty, aux, tasks, shaping, the model options
declared with a name part, the aux balance, precision, seed, profile), followed, when another identifying field
differs from its profile's value, by those fields (`swept`): a sweep over any identifying field
(``--set ppo.lr=...``) gets one run dir per value. What is identifying is `TrainConfig.identity()`; the run dir that
the name names is `emml.runs.rundir.run_dir`.

Importing this module imports no torch: the model registry is read only for a run that sets its fusion's own options.
"""

from __future__ import annotations

import hashlib
import json
import re

from emml.config.profiles import Profile, load_profiles, resolve_profile
from emml.config.schema import NAME_PART, SHARED_MODEL_OPTIONS, ModelConfig, TrainConfig, option_fields

NAMED = ("table", "model", "aux", "seed", "profile", "precision", "env.difficulty", "env.tasks", "env.shaping",
         "ppo.aux_balance")  # fmt: skip
"""Identifying fields the run dir's path spells out (its table folder, `spelled_name`): never repeated by `swept`;
so are the model options declared with a name part (`named`)."""
RESOLVED = ("env.vocabulary", "env.aux_words", "env.aux_labels")
"""Identifying fields that the trainer resolves at start (a vocabulary source becomes its word list, the aux words
are the dataset's, aux_labels follows aux): compared on resume, never part of the name (it would change when
resolved)."""
NAME_CHARS = re.compile(r"[A-Za-z0-9._+-]+")
"""What a part of a run's name may hold: it names a folder (no '/', no space)."""
SWEPT_DIGEST_OVER = 48
"""Characters above which the swept fields are named by a digest instead of spelled out."""


def run_name(cfg: TrainConfig, profile: Profile | None = None) -> str:
    """The run's name: `spelled_name` (with the options the model's fusion declares), then ``+field=value`` per
    `swept` field (a digest when long); ``profile``: `cfg.profile` resolved, when the caller holds it."""
    name, extra = spelled_name(cfg, fusion_options(cfg)), swept(cfg, profile)
    if not extra:
        return name
    spelled = "+".join(f"{k}={_short(v)}" for k, v in extra.items())
    if len(spelled) > SWEPT_DIGEST_OVER or not all(c.isalnum() or c in "+=._-" for c in spelled):
        spelled = "x" + hashlib.sha256(json.dumps(extra, sort_keys=True).encode()).hexdigest()[:8]
    return f"{name}+{spelled}"


def spelled_name(cfg: TrainConfig, fusion_options: type | None) -> str:
    """The readable part of the name, from the fields that define the experiment: model, difficulty, aux, tasks,
    shaping, the model options a run sets that are declared with a name (`emml.config.schema.model_option`: the
    shared ones of `ModelConfig`, sentence readout and activation, then those of ``fusion_options``, the model's
    fusion's declared options class, e.g. Dual-Attention's state temperature, Eq. 1 words and answer loss's reach),
    the aux loss's balance, precision, seed, profile. ``fusion_options`` may be None when `model_options` sets only
    shared options (`run_name` asks the model registry for it only then)."""
    parts = [cfg.model, cfg.env.difficulty, "aux" if cfg.aux else "noaux"]
    if cfg.env.tasks != "both":
        parts.append(f"{cfg.env.tasks}only")
    if not cfg.env.shaping:
        parts.append("noshaping")
    own = {k: v for k, v in cfg.model_options.items() if k not in SHARED_MODEL_OPTIONS}
    if own and fusion_options is None:
        raise ValueError(f"spelled_name: model options {sorted(own)} need the declared options of {cfg.model!r}")
    parts += option_name_parts(ModelConfig, cfg.model_options)  # opt-in: x_sent's readout, activation
    if fusion_options is not None:  # opt-in: the fusion's, e.g. Dual-Attention's 'xs0.25', 'eq1content', 'ansgate'
        parts += option_name_parts(fusion_options, own)
    if cfg.ppo.aux_balance != "none":  # opt-in: the aux cross-entropy balanced per word
        parts.append(f"auxbal{cfg.ppo.aux_balance}")
    if cfg.precision != "fp32":  # a bf16 run is another experiment: beside the fp32 run, not resuming it
        parts.append(cfg.precision)
    return "-".join([*parts, f"s{cfg.seed}", cfg.profile])


def fusion_options(cfg: TrainConfig) -> type | None:
    """The options class the run's model's fusion declares (`emml.models.Fusion.options`); None when `model_options`
    sets none but the shared ones (`ModelConfig`), so that naming such a run reads no model registry (which imports
    torch and loads the plugins)."""
    if not set(cfg.model_options) - set(SHARED_MODEL_OPTIONS):
        return None
    from emml.models import fusion_options as declared  # the model registry: a plugin's model needs its plugin

    return declared(cfg.model)


def named(cfg: TrainConfig) -> tuple[str, ...]:
    """The identifying fields (dotted) the run's name spells: `NAMED`, and the model options declared with a name
    part (`emml.config.schema.model_option`), the shared ones and those of the model's fusion."""
    options = [*named_options(ModelConfig)]
    if (declared := fusion_options(cfg)) is not None:
        options += named_options(declared)
    return (*NAMED, *(f"model_options.{name}" for name in options))


def swept(cfg: TrainConfig, profile: Profile | None = None) -> dict:
    """Identifying fields (dotted) that differ from the profile's value and that the readable name does not spell:
    {field: value}, sorted. Empty for every run a table or profile declares as-is."""
    base, own = _baseline(cfg, profile), flat(cfg.identity())
    skip = set(named(cfg)) | set(RESOLVED)
    return {k: own[k] for k in sorted(own) if k not in skip and own[k] != base.get(k)}


def _baseline(cfg: TrainConfig, profile: Profile | None = None) -> dict:
    """The flat identity of the run its profile would give (same model, difficulty, aux, seed): what `swept`
    compares with. ``profile``: the run's profile when the caller holds it resolved; otherwise `cfg.profile` is
    looked up, and a profile that is not in the profiles file compares with TrainConfig's defaults."""
    if profile is None and cfg.profile in load_profiles():
        profile = resolve_profile(cfg.profile)
    if profile is not None:
        base = profile.config(cfg.env.difficulty, model=cfg.model, aux=cfg.aux, seed=cfg.seed)
    else:
        base = TrainConfig(model=cfg.model, aux=cfg.aux, seed=cfg.seed, profile=cfg.profile)
    return flat(base.identity())


def flat(d: dict, prefix: str = "") -> dict:
    """{'env': {'height': 60}} -> {'env.height': 60} (tuples as lists: a config read back from JSON has lists)."""
    out = {}
    for k, v in d.items():
        if isinstance(v, dict) and k in ("env", "ppo", "model_options"):
            out.update(flat(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = list(v) if isinstance(v, tuple) else v
    return out


def _short(v) -> str:
    return spell(v) if isinstance(v, float) else str(v)


def spell(value) -> str:
    """A number as a run name spells it, exactly (issue 65: ``f"{value:g}"`` rounded 1000001 to '1e+06', so two
    warm-ups named one run dir): an integer in full ('400000'), a float as ``:g`` writes it when that reads back as
    the same float ('0.25', '1e-05': every name so far), else its repr. A value a run dir's name cannot hold (not
    finite) is a ValueError."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return str(value)
    if isinstance(value, int):
        return str(value)
    if value != value or value in (float("inf"), float("-inf")):
        raise ValueError(f"{value!r} is not a finite number: a run name cannot hold it")
    short = f"{value:g}"
    return short if float(short) == value else repr(value)


def named_options(options: type) -> tuple[str, ...]:
    """The options of ``options`` (a declared options class) that a run's name spells when a run sets them."""
    return tuple(name for name, f in option_fields(options).items() if NAME_PART in f.metadata)


def option_name_parts(options: type, values: dict) -> list[str]:
    """The run name's parts of the options in ``values`` (`TrainConfig.model_options`) that ``options`` declares with
    a name (`emml.config.schema.model_option`) and that ``values`` sets to another value than the default, in
    declaration order."""
    parts = []
    for name, f in option_fields(options).items():
        spelled = f.metadata.get(NAME_PART)
        if spelled is None or name not in values or values[name] == f.default:
            continue
        value = values[name]
        try:
            part = spelled.replace("{}", spell(value))
        except ValueError as e:
            raise ValueError(f"model_options.{name}={value!r}: {e}") from None
        if not NAME_CHARS.fullmatch(part):
            raise ValueError(
                f"model_options.{name}={value!r}: a run name cannot hold it (its part {part!r}); allowed: letters, "
                "digits, '.', '_', '+' and '-'"
            )
        parts.append(part)
    return parts
