"""Re-score a finished run with the final-evaluation protocol (issue 33): its checkpoint played greedily over
`final_eval_episodes` per (task, split) from the episode seed `EVAL_SEED` (§5.1's accuracy, emml/eval/evaluate.py), its
results.json metrics and results-table row rewritten. The training provenance stays (run_name, frames, seed,
git_sha, run_id); the row adds the code that scored it (`scored_sha`), the episodes and their seed.

Runs finished before issue 33 were scored over the profile's `eval_episodes` (quick: 100), too few to compare
runs (docs/fidelity.md, "Trainer"). Re-scoring is idempotent: a run whose results.json already holds the asked
protocol is not played again, its row is only (re)recorded (`--force` plays it again).

Per question (issue 81, `rescore_questions`, `emml rescore --questions`): a run finished before its evaluation counted
EQA per question gets the counts by replaying its final evaluation's EQA episodes (its row's eval_seed and
eval_episodes), checked against its row: the counts of each EQA setting must sum to the row's eqa_train / eqa_test
exactly, else `NotReproduced` and nothing is written. Its row is never changed; results.json gains "questions" and
results/<table>/<profile>-questions.csv the run's rows (emml/runs/results.py).
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from emml.config.profiles import refuse_committed
from emml.config.schema import TrainConfig
from emml.runs.checkpoint import load_checkpoint
from emml.runs.naming import run_name
from emml.runs.results import (
    BOOLEAN,
    INTEGER,
    LATE_INTEGER,
    TEXT,
    questions_path,
    read_questions,
    read_results,
    upsert_questions,
)
from emml.runs.rundir import (
    CHECKPOINT,
    EVAL_SEED,
    RESULTS,
    git_sha,
    results_csv,
    run_identity,
    save_results,
    write_json,
)
from emml.runs.runlock import hold_run


class NotFinished(ValueError):
    """The run's checkpoint is not at the end of its training: there is no final score to replace."""


class NoProvenance(ValueError):
    """The run has neither a results.json nor a results-table row of this training to take its provenance from."""


class NotReproduced(ValueError):
    """Replayed, a run's EQA episodes do not sum to its row's score: its per-question counts would not be of the
    episodes that made the row, so none is written (the message names the run, the setting and both numbers)."""


@dataclass
class Rescored:
    """One re-scored run."""

    run_dir: Path
    """The run directory (its checkpoint.pt and results.json)."""
    before: dict
    """Its metrics before, with the episodes and seed they were measured on ('eval_episodes', 'eval_seed')."""
    after: dict
    """Its metrics now, likewise."""
    played: bool
    """False when results.json already held this protocol: nothing played, the row recorded again."""
    csv: Path | None
    """The results table whose row was upserted; None when not recorded (``record=False``)."""


def rescore(
    run: Path,
    episodes: int = 0,
    seed: int = EVAL_SEED,
    record: bool = True,
    force: bool = False,
    results_root: str | None = None,
    device: str = "cpu",
) -> Rescored:
    """Re-score the finished run at ``run`` (its directory or its checkpoint) over ``episodes`` per (task, split)
    (0: its config's `final_eval_episodes`; a checkpoint from before the field reads its default) from episode seed
    ``seed``. Writes results.json atomically, then (``record``) upserts the row of its results table (the
    checkpoint's `results_root`, or ``results_root``). Nothing is written unless every score was measured."""
    from emml.eval.evaluate import evaluate_checkpoint

    with finished_run(run, results_root) as (rdir, ckpt, cfg):
        payload = training_record(rdir, ckpt, cfg)
        episodes = episodes or cfg.final_eval_episodes
        before = _protocol(payload)
        played = force or (payload.get("eval_episodes"), payload.get("eval_seed")) != (episodes, seed)
        if played:
            scores = evaluate_checkpoint(rdir / CHECKPOINT, episodes, seed, device=device)
            payload = training_record(rdir, ckpt, cfg)  # read again: keys written meanwhile (minutes) are kept
            payload = {
                **{k: v for k, v in payload.items() if k != "metrics"},
                "eval_episodes": episodes,
                "eval_seed": seed,
                "scored_sha": git_sha(),
                "metrics": {**payload["metrics"], **scores},  # other columns (Table 4's transfer scores) stay
            }
            payload.pop("questions", None)  # counts of the old protocol's episodes are not this score's
            if getattr(scores, "questions", None):
                payload["questions"] = scores.questions
        if played or record:
            save_results(rdir, payload, cfg, record=record)
    return Rescored(rdir, before, _protocol(payload), played, results_csv(cfg) if record else None)


@contextmanager
def finished_run(run: str | Path, results_root: str | None = None) -> Iterator[tuple[Path, dict, TrainConfig]]:
    """The finished run at ``run`` (its directory or its checkpoint), held (no training of it meanwhile:
    emml/runs/runlock.py): its directory, checkpoint and config (``results_root`` in place of its own when given);
    a run without a checkpoint, or not finished, fails by name (`check_finished`)."""
    rdir = Path(run) if Path(run).is_dir() else Path(run).parent
    if not (rdir / CHECKPOINT).is_file():
        raise FileNotFoundError(f"{run}: no run directory with a {CHECKPOINT}")
    with hold_run(rdir):
        ckpt = load_checkpoint(rdir / CHECKPOINT)
        cfg = TrainConfig.from_dict(ckpt["config"])
        if results_root is not None:
            cfg.results_root = results_root
        check_finished(rdir, ckpt, cfg)
        yield rdir, ckpt, cfg


def check_finished(rdir: Path, ckpt: dict, cfg: TrainConfig) -> None:
    """NotFinished unless the checkpoint holds the whole run its config asks for."""
    target = cfg.num_updates * cfg.frames_per_update
    if not (ckpt.get("finished") and ckpt["frames"] >= target):
        raise NotFinished(
            f"{rdir} holds an unfinished run (frame {ckpt['frames']:,} of {target:,}): only a finished run's score "
            "is replaced; finish it first (`emml train` with its options resumes it)"
        )


def training_record(rdir: Path, ckpt: dict, cfg: TrainConfig) -> dict:
    """The run's results.json payload; when absent, rebuilt from its row in the results table (a run dir whose
    results.json was not kept). Either must describe this checkpoint's training (run_id, frames), else
    NoProvenance."""
    path = rdir / RESULTS
    if path.exists():
        payload = json.loads(path.read_text())
        _same_training(payload, ckpt, path)
        return payload
    table = results_csv(cfg)
    rows = read_results(table)
    rows = rows[rows["run_name"] == run_name(cfg)]
    if rows.empty:
        raise NoProvenance(
            f"{rdir} has no {RESULTS} and {table} has no row {run_name(cfg)!r}: the training's provenance (its "
            "git sha) is unknown, so it is not re-scored"
        )
    row = rows.iloc[0].to_dict()
    _same_training(row, ckpt, table)
    identity = {*TEXT, *INTEGER, *LATE_INTEGER, *BOOLEAN}
    payload = {
        **run_identity(cfg),
        "frames": ckpt["frames"],
        "git_sha": row["git_sha"],
        "run_id": ckpt["run_id"],
        "eval_episodes": int(row["eval_episodes"]),
        "config": json.loads(json.dumps(ckpt["config"])),  # what the run trained with, as _write_results keeps it
    }
    if pd.notna(row.get("eval_seed")):
        payload["eval_seed"] = int(row["eval_seed"])
    if row.get("scored_sha"):
        payload["scored_sha"] = row["scored_sha"]
    payload["metrics"] = {k: float(v) for k, v in row.items() if k not in identity and pd.notna(v)}
    return payload


def _same_training(record: dict, ckpt: dict, where: Path) -> None:
    if (str(record["run_id"]), int(record["frames"])) != (str(ckpt["run_id"]), ckpt["frames"]):
        raise NoProvenance(
            f"{where} describes another training of this run (run id {record['run_id']}, {int(record['frames']):,} "
            f"frames) than its checkpoint (run id {ckpt['run_id']}, {ckpt['frames']:,} frames): not re-scored"
        )


def _protocol(payload: dict) -> dict:
    return {**payload["metrics"], "eval_episodes": payload.get("eval_episodes"), "eval_seed": payload.get("eval_seed")}


@dataclass
class QuestionsRescored:
    """One run's EQA per question, replayed (`rescore_questions`)."""

    run_dir: Path
    """The run directory."""
    run_name: str
    """Its name: its rows' key in the results table and the per-question file."""
    questions: dict
    """{'eqa_test': {question: {'successes': k, 'episodes': n}}}: the counts, which sum to the row's scores."""
    played: bool
    """False when the per-question file already held this training's counts (nothing played, nothing written)."""
    seconds: float
    """Wall-clock seconds the replay took (0 when not played)."""
    csv: Path
    """The per-question file (results/<table>/<profile>-questions.csv)."""
    compiled: bool = False
    """Whether the counts are of the compiled replay (`rescore_questions`: the eager one did not reproduce the row)."""


def rescore_questions(
    run: Path, results_root: str | None = None, device: str = "cpu", force: bool = False
) -> QuestionsRescored:
    """Count EQA's successes per question for the finished run at ``run`` by replaying its final evaluation's EQA
    episodes (its results row's eval_seed, default `EVAL_SEED`, and eval_episodes; the same envs in lockstep as
    `evaluate`). Each EQA setting's counts must reproduce the row's score exactly (`NotReproduced` otherwise, nothing
    written); then results.json gains "questions" and the per-question file the run's rows. The results row is not
    written. A run whose counts for this training (run_id) are in the file already is not played (``force``: it is).

    The replay runs the model eagerly; where that does not reproduce the row and the run's `TrainConfig.compile`
    compiles on ``device`` (emml.models.compiled.wants_compile, the trainer's rule), it is played again compiled, as the
    trainer's final evaluation ran it (emml/rl/trainer.py), and that must reproduce the row exactly. The two agree
    within float tolerance, and a greedy argmax near a tie can follow the last bits: Table 3's w/o GA2 Easy No Aux
    seed 0 replayed eagerly EQA train 107/500, test 78/500; compiled 105/500 and 42/500, its row (0.210, 0.084)."""
    from emml.eval.evaluate import PER_QUESTION, evaluate_checkpoint
    from emml.models.compiled import wants_compile

    with finished_run(run, results_root) as (rdir, ckpt, cfg):
        name, table = run_name(cfg), results_csv(cfg)
        row = _row(table, name, ckpt)
        out = questions_path(table)
        refuse_committed(cfg.profile, out, "per-question results CSV")  # smoke numbers are not results
        kept = read_questions(out)
        kept = kept[(kept["run_name"] == name) & (kept["run_id"] == str(ckpt["run_id"]))]
        if not kept.empty and not force:
            return QuestionsRescored(rdir, name, _nested(kept), False, 0.0, out, False)
        episodes = int(row["eval_episodes"])
        seed = int(row["eval_seed"]) if pd.notna(row.get("eval_seed")) else EVAL_SEED
        start = time.perf_counter()
        scores = evaluate_checkpoint(rdir / CHECKPOINT, episodes, seed, device=device, tasks=PER_QUESTION)
        compiled = False
        try:
            check_reproduced(name, scores.questions, row, episodes)
        except NotReproduced as eager:
            if not wants_compile(cfg.compile, device):
                raise
            # the trainer scored it compiled (emml/rl/trainer.py, TrainConfig.compile): replayed so, as it played
            scores = evaluate_checkpoint(
                rdir / CHECKPOINT, episodes, seed, device=device, tasks=PER_QUESTION, compiled=True
            )
            compiled = True
            try:
                check_reproduced(name, scores.questions, row, episodes)
            except NotReproduced as again:
                raise NotReproduced(f"{eager} (played eagerly); compiled, as its trainer plays: {again}") from None
        seconds = time.perf_counter() - start
        if (rdir / RESULTS).exists():
            payload = training_record(rdir, ckpt, cfg)  # read now: keys written meanwhile are kept
            write_json(rdir / RESULTS, {**payload, "questions": scores.questions})
        upsert_questions(out, name, str(ckpt["run_id"]), scores.questions)
    return QuestionsRescored(rdir, name, scores.questions, True, seconds, out, compiled)


def check_reproduced(name: str, questions: dict, row: dict, episodes: int) -> None:
    """NotReproduced unless, for each per-question setting the row scores, the counts cover ``episodes`` episodes
    and their successes over them equal the row's value (to 1e-9; one episode of 500 is 2e-3)."""
    wrong = []
    for setting, counts in questions.items():
        if setting not in row or pd.isna(row[setting]):
            wrong.append(f"{setting}: replayed, but the row has no {setting}")
            continue
        k = sum(c["successes"] for c in counts.values())
        n = sum(c["episodes"] for c in counts.values())
        if n != episodes or abs(k / n - float(row[setting])) > 1e-9:
            wrong.append(
                f"{setting} per question sums to {k}/{n} = {k / n:.4f}, its row reads {float(row[setting]):.4f}"
            )
    if wrong:
        raise NotReproduced(f"{name}: {'; '.join(wrong)}: its per-question counts are not written")


def _row(table: Path, name: str, ckpt: dict) -> dict:
    """The run's results row, of this checkpoint's training (run_id, frames), else NoProvenance."""
    rows = read_results(table)
    rows = rows[rows["run_name"] == name]
    if rows.empty:
        raise NoProvenance(f"{table} has no row {name!r}: no score to count per question")
    row = rows.iloc[0].to_dict()
    _same_training(row, ckpt, table)
    return row


def _nested(rows: pd.DataFrame) -> dict:
    """Per-question rows of one run back to `Scores.questions`' shape."""
    out: dict = {}
    for r in rows.itertuples():
        counts = {"successes": int(r.successes), "episodes": int(r.episodes)}
        out.setdefault(f"{r.task}_{r.split}", {})[r.question] = counts
    return out
