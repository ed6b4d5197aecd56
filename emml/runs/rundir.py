"""A run's one owner: its directory and files, its identity, its results and provenance, its model.

A run lives in ``<run_root>/<table>/<run name>/``:

- ``checkpoint.pt``: model, optimizer, RNG states, counters, vocabulary, config, MLflow run id (`save_checkpoint`);
- ``metrics.csv``: every metric point, step,key,value (emml.runs.tracking.Tracker.mirror_to);
- ``results.json``: the final score with its provenance and config (`save_results`), its row in
  ``<results_root>/<table>/<profile>.csv`` (`record_result`);
- ``run.lock``: held while a process trains or re-scores it (emml/runs/runlock.py);
- ``segments.json``: each session's commit and the frame it started from (emml/runs/segments.py), read into
  results.json's ``segments`` and into when the run last began training (`last_started`).

Identity. What a run *is* is `TrainConfig.identity()`: every field but those of how it runs (`TrainConfig.RUNTIME`:
device, threads, workers, roots, cadences, the frame target). Its name is `emml.runs.naming.run_name` (the fields a
reader looks for, then any other identifying field that differs from its profile's value): a sweep over any
identifying field (``--set ppo.lr=...``) gets one run dir per value, and a rerun resumes only a run of the same
identity (`check_resumable`). The results row, the MLflow tags and results.json name a run by `run_identity`.

Importing this module imports no torch (reports read runs through it): checkpoints and models are loaded in the
functions that need them.
"""

from __future__ import annotations

import json
import subprocess
from dataclasses import dataclass
from pathlib import Path

from emml.config.paths import project_path, project_root
from emml.config.schema import TrainConfig, apply_overrides
from emml.runs.atomic import write_text
from emml.runs.naming import flat, run_name
from emml.runs.segments import noted, run_segments

CHECKPOINT = "checkpoint.pt"
"""The run's state (`save_checkpoint`): written every `checkpoint_every` updates, at a stop, and at the end."""
METRICS = "metrics.csv"
"""Every metric point of the run (step,key,value), mirrored beside its checkpoint
(emml.runs.tracking.Tracker.mirror_to)."""
RESULTS = "results.json"
"""The final score, its provenance and the config the run trained with (`save_results`)."""
EVAL_SEED = 10_000
"""Episode seeds of every greedy evaluation of a run: EVAL_SEED, EVAL_SEED + 1, … (emml.eval.evaluate), recorded as
``eval_seed`` beside the score."""
RUN_FILES = (CHECKPOINT, METRICS, RESULTS)
"""Files any of which makes a folder a run dir."""


def git_sha() -> str:
    """The short sha of the checkout's HEAD ('unknown' outside git): a run's provenance."""
    try:
        out = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=project_root(), capture_output=True, text=True, timeout=5
        )
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


# --- identity ------------------------------------------------------------------------------------------------------
def run_dir(cfg: TrainConfig) -> Path:
    """``<run_root>/<table>/<run name>`` (the run root relative to the project unless absolute)."""
    return project_path(cfg.run_root) / cfg.table / run_name(cfg)


def path_of(run_root: str | Path, table: str, name: str) -> Path:
    """The run dir of run ``name`` of ``table`` under ``run_root`` (a results row names its run so)."""
    return project_path(run_root) / table / name


def finished_run(directory: Path) -> bool:
    """Whether ``directory`` holds a finished run: its checkpoint says so (``finished``) and its results.json is
    there. What the launcher skips, and what a report may show beside a result."""
    checkpoint = Path(directory) / CHECKPOINT
    if not (checkpoint.exists() and (Path(directory) / RESULTS).exists()):
        return False
    from emml.runs.checkpoint import load_checkpoint  # torch: loaded when a checkpoint is read, not for reports

    try:
        return bool(load_checkpoint(checkpoint, require=()).get("finished"))
    except Exception:  # a checkpoint we cannot read is not finished; the trainer will say why
        return False


def config_of(directory: Path) -> TrainConfig | None:
    """The config the run in ``directory`` trained with: its results.json's, else its checkpoint's; None when it has
    neither."""
    saved = saved_config(directory)
    if saved is None and (Path(directory) / CHECKPOINT).exists():
        saved = read_checkpoint(Path(directory) / CHECKPOINT)["config"]
    return TrainConfig.from_dict(saved) if saved is not None else None


def variant_dir(cfg: TrainConfig, run_root: str | Path, **fields) -> Path:
    """The run dir, under ``run_root``, of the run that differs from ``cfg``'s in the TrainConfig ``fields`` (e.g.
    the No-Aux run beside an Aux run: ``aux=False``)."""
    other = apply_overrides(TrainConfig.from_dict(cfg.to_dict()), {**fields, "run_root": str(run_root)})
    return run_dir(other)


def run_identity(cfg: TrainConfig) -> dict:
    """What names a run in its results.json, results row and MLflow tags (its provenance follows: frames, git sha,
    run id)."""
    return {
        "run_name": run_name(cfg),
        "table": cfg.table,
        "model": cfg.model,
        "difficulty": cfg.env.difficulty,
        "aux": cfg.aux,
        "seed": cfg.seed,
        "profile": cfg.profile,
    }


def run_tags(cfg: TrainConfig, git_sha: str, allocator: str) -> dict:
    """The run's MLflow tags: its identity (less its name, the MLflow run name), the setting a reader filters
    on, its provenance and its checkpoint's path."""
    identity = run_identity(cfg)
    name = identity.pop("run_name")
    return {
        **identity,
        "git_sha": git_sha,
        "allocator": allocator,
        "tasks": cfg.env.tasks,
        "shaping": cfg.env.shaping,
        "precision": cfg.precision,
        "checkpoint": str(path_of(cfg.run_root, cfg.table, name) / CHECKPOINT),
    }


class ConfigMismatch(ValueError):
    """A rerun whose identity differs from the checkpoint's run (the message names the fields)."""


def check_resumable(saved: dict, cfg: TrainConfig, path: Path) -> None:
    """A rerun resumes only the same experiment: identifying fields that differ fail by name before anything is
    touched. ``saved``: the checkpoint's config (`TrainConfig.to_dict`); a field added since it was written reads as
    its default (the run it describes is unchanged); how the run runs (`TrainConfig.RUNTIME`) may differ."""
    defaults = flat(TrainConfig().identity())
    old = {**defaults, **{k: v for k, v in flat(saved).items() if k.split(".")[0] not in TrainConfig.RUNTIME}}
    new = flat(cfg.identity())
    diffs = [k for k in sorted(set(old) | set(new)) if old.get(k) != new.get(k)]  # an option set on one side only:
    # absent (None) on the other
    if diffs:
        raise ConfigMismatch(
            f"{path} holds a run with a different config ({', '.join(diffs)}); use another seed/table/run_root, "
            "or delete that run directory"
        )


# --- checkpoint and model ------------------------------------------------------------------------------------------
def read_checkpoint(path: Path) -> dict:
    """A checkpoint's payload (`save_checkpoint`), on the CPU."""
    from emml.runs.checkpoint import load_checkpoint  # torch: loaded when a checkpoint is read, not for reports

    return load_checkpoint(path)


def load_model(path, device: str = "cpu", control: str | None = None):
    """(model, TrainConfig) rebuilt from a checkpoint with its own config and vocabulary; ``control`` (one of
    `emml.config.schema.CONTROLS`) replaces the run's diagnostic control, for evaluation (same weights)."""
    from emml.models import build_model  # torch: loaded when a model is, not for reports

    ckpt = read_checkpoint(path)
    cfg = TrainConfig.from_dict(ckpt["config"])
    if control is not None:
        cfg.model_options = {**cfg.model_options, "control": control}
    env = cfg.env
    from emml.tasks.language import load_dataset

    model = build_model(cfg.model, len(ckpt["vocabulary"]), env.height, env.width, env.max_steps, **cfg.model_options)
    model.read_words(tuple(ckpt["vocabulary"]), load_dataset(env.dataset).content_words())
    model.load_state_dict(ckpt["model"])
    if model.cfg.control == "type_gate":  # the word-type gate needs the run's words and the dataset's types
        from emml.models.type_gate import TypeGate

        model.type_gate = TypeGate(tuple(ckpt["vocabulary"]), load_dataset(env.dataset))
    return model.to(device), cfg


# --- results -------------------------------------------------------------------------------------------------------
class RunDirError(ValueError):
    """A run dir whose results.json or metrics.csv cannot be read (the message names the file)."""


def read_results(path: Path) -> dict:
    """A run's results.json (``path``: the file or its run dir); RunDirError naming the file unless it is a JSON
    object with 'run_id' and 'table'."""
    path = Path(path)
    if path.is_dir():
        path = path / RESULTS
    data = _json_object(path)
    missing = [k for k in ("run_id", "table") if not data.get(k)]
    if missing:
        raise RunDirError(f"{path}: no {' and no '.join(map(repr, missing))}")
    return data


def saved_config(directory: Path) -> dict | None:
    """The config a run trained with, from its results.json ("config"); None when the file or its "config" is
    absent (a run finished before the trainer wrote it: `emml backfill-config`)."""
    path = Path(directory) / RESULTS
    if not path.exists():
        return None
    return _json_object(path).get("config")


def last_started(directory: str | Path) -> str:
    """When the run in ``directory`` last began training, UTC ISO 8601: its last noted session (segments.json,
    emml/runs/segments.py), else results.json's ``started_at`` (a run from before segments were noted); "" when
    neither says (an older run)."""
    times = [s.get("started_at") for s in noted(directory)]
    if not times:
        try:
            times = [read_results(directory).get("started_at")]
        except RunDirError:  # absent or damaged (named where a report reads it): no time
            times = []
    return max((t for t in times if isinstance(t, str)), default="")


def _json_object(path: Path) -> dict:
    """The JSON object in ``path``; RunDirError naming the file (and the line) unless it holds one. results.json is
    written whole (`write_json`), so a file that does not parse was damaged otherwise: it is named, never guessed."""
    try:
        data = json.loads(path.read_bytes().decode("utf-8"))
    except OSError as e:
        raise RunDirError(f"{path}: cannot be read ({e.strerror})") from None
    except UnicodeDecodeError as e:
        raise RunDirError(f"{path}: not UTF-8 text (byte {e.start})") from None
    except json.JSONDecodeError as e:
        raise RunDirError(f"{path}: not JSON ({e.msg}, line {e.lineno} column {e.colno})") from None
    if not isinstance(data, dict):
        raise RunDirError(f"{path}: not a JSON object")
    return data


def write_json(path: Path, payload: dict) -> None:
    """Atomically (a temporary file, then a rename), as 2-space JSON; a full disk names both files."""
    write_text(path, json.dumps(payload, indent=2))


def results_payload(
    cfg: TrainConfig, metrics: dict, frames: int, git_sha: str, run_id: str, times: dict | None = None
) -> dict:
    """What results.json holds: the run's identity, its provenance (``git_sha``: the commit that finished it;
    ``segments``: each commit it trained under with its frames, emml/runs/segments.py), when it trained (``times``:
    `TIMES`), how its score was measured, the score and the config it trained with (reports state its deviations from
    the paper)."""
    return {
        **run_identity(cfg),
        "frames": frames,
        "git_sha": git_sha,
        "run_id": run_id,
        **(times or {}),
        "segments": run_segments(path_of(cfg.run_root, cfg.table, run_name(cfg)), frames, git_sha),
        "eval_episodes": cfg.final_eval_episodes,  # the score's: the final evaluation's
        "eval_seed": EVAL_SEED,
        "metrics": metrics,
        "config": cfg.to_dict(),
    }


def save_results(directory: Path, payload: dict, cfg: TrainConfig, record: bool = True) -> None:
    """Write a run's results.json atomically, then (``record``) upsert its row in the results CSV (`record_result`)."""
    write_json(Path(directory) / RESULTS, payload)
    if record:
        record_result(payload, cfg)


def results_csv(cfg: TrainConfig) -> Path:
    """``<results_root>/<table>/<profile>.csv``: the run's results table."""
    return project_path(cfg.results_root) / cfg.table / f"{cfg.profile}.csv"


ROW_ONLY = ("tasks", "shaping", "precision")
"""Columns `record_result` adds to a results row that are not keys of results.json."""
TIMES = ("started_at", "ended_at")
"""When the run trained, UTC ISO 8601 (results.json, from its checkpoint's ``started_at``): the start of its first
session and the end of its final evaluation; the MLflow run's own start and end where it is imported
(emml/runs/import_runs.py). Not columns of the results row: a reader from before them (a pinned campaign) reads an
unknown column as a metric."""


FINAL = "final/"
"""Prefix of the final score's metrics in the MLflow run (results.json "metrics"): ``final/sgn_test``…, apart from
the periodic evaluations' ``eval/sgn_test`` curve."""
RENAMED = {"frames": "trained_frames", "eval_episodes": "score_eval_episodes", "eval_seed": "score_eval_seed"}
"""results.json keys tagged under another name in the MLflow run, apart from the params of the same name: ``frames``
is the frames trained (whole updates: 1,500,160) where the param ``frames`` is the config's target (1,500,000);
``eval_episodes`` and ``eval_seed`` are the final score's (500 episodes, `final_eval_episodes`) where the param
``eval_episodes`` is the periodic evaluations' (100)."""


def score_tags(results: dict) -> dict:
    """How the final score was measured, as tags (`RENAMED`): the trainer sets them on its run when it writes
    results.json, and the import (emml/runs/import_runs.py) on the run it makes of a run dir, so that both read
    alike."""
    return {RENAMED[k]: results[k] for k in RENAMED if results.get(k) is not None}


def utc_ms(text: str) -> int:
    """An ISO 8601 time (results.json ``started_at``, `TIMES`) as ms since the epoch; naive times are UTC."""
    from datetime import datetime, timezone

    when = datetime.fromisoformat(str(text).replace("Z", "+00:00"))
    if when.tzinfo is None:
        when = when.replace(tzinfo=timezone.utc)
    return int(when.timestamp() * 1000)


JSON_ONLY = ("segments", "questions")
"""Keys of results.json that are not columns of the results row (as `TIMES`: a pinned campaign's reader from before
them would read an unknown column as a metric): the commits a run trained under (emml/runs/segments.py); EQA's counts
per question (emml.eval.evaluate.Scores.questions), whose rows go to the per-question file (emml/runs/results.py)."""


def record_result(payload: dict, cfg: TrainConfig) -> Path:
    """Upsert the run's row (keyed by run name) in its results CSV (emml.runs.results): results.json's keys but the
    metrics, config, `TIMES` and `JSON_ONLY`, then `ROW_ONLY`, then the metrics."""
    from emml.config.profiles import refuse_committed
    from emml.runs.results import questions_path, upsert_questions, upsert_result

    refuse_committed(cfg.profile, results_csv(cfg), "results CSV")  # smoke numbers are not results
    row = {k: v for k, v in payload.items() if k not in ("metrics", "config", *TIMES, *JSON_ONLY)}
    row.update(tasks=cfg.env.tasks, shaping=cfg.env.shaping, precision=cfg.precision, **payload["metrics"])
    if payload.get("questions"):  # EQA per question, beside the table (emml.runs.results, issue 81)
        upsert_questions(questions_path(results_csv(cfg)), payload["run_name"], payload["run_id"], payload["questions"])
    return upsert_result(results_csv(cfg), row)


@dataclass
class RunResult:
    """What training a run returns."""

    run_dir: Path
    """Its directory."""
    run_id: str
    """Its MLflow run id."""
    frames: int
    """Frames trained."""
    metrics: dict
    """Its final score (greedy accuracy per task and split)."""
    resumed: bool = False
    """Resumed from a checkpoint."""
    skipped: bool = False
    """Already finished: nothing trained, its row recorded again."""
